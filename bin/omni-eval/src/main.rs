//! omni-eval: accuracy of a point cloud — primitive fits or comparison with a scene's truth.

use clap::{Parser, Subcommand};
use omni_cli::CliError;
use omni_cloud::eval::{self, Comparison, compare_with_scene};
use omni_cloud::filter::CropBox;
use omni_cloud::fit::{ErrorStats, FitOptions, Shape, ShapeKind};
use omni_formats::read_doc;
use omni_formats::rig::{BoardPosesFile, RigFile};
use omni_formats::scene::SceneFile;
use omni_formats::transform::TransformFile;
use omni_geom::Point3;
use std::io::Write;
use std::path::{Path, PathBuf};

#[derive(Parser, Debug)]
#[command(
    // Help is printed as written, unwrapped: examples stay one line for copy and paste.
    term_width = 0,
    version,
    about = "Measure a point cloud's accuracy: fit a primitive, or compare with a scene's true surfaces.",
    after_help = "Examples:\n  \
omni-eval fit --shape sphere --radius 50 --centre 500,0,0 sphere.ply\n  \
omni-eval fit --shape plane --crop 400,-200,-150,600,200,150 --json plane.ply\n  \
omni-eval compare --scene scene.json cloud.ply\n\n\
Errors are signed distances (mm) to the surface, positive outside the object (for a plane: towards \
the sensor). Statistics: mean signed error, standard deviation (n-1), RMS, max |error|; `fit` takes \
them over the points within max(--inlier-mm, 3.5 robust σ) of the shape, `compare` over each \
object's points within --max-distance-mm of it.\n\
Exit codes: 0 ok, 1 bad input, 2 usage error."
)]
struct Args {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Fit a primitive (RANSAC, least squares on its inliers, then on the points within 3.5 robust
    /// σ of that shape) and report the residuals.
    #[command(after_help = "Example:\n  omni-eval fit --shape sphere --radius 50 --centre 500,0,0 sphere.ply")]
    Fit {
        /// plane, sphere, cylinder or cone.
        #[arg(long)]
        shape: ShapeKind,
        /// Use only points inside this box (mm).
        #[arg(long, value_name = "XMIN,YMIN,ZMIN,XMAX,YMAX,ZMAX", allow_hyphen_values = true)]
        crop: Option<String>,
        /// RANSAC inlier threshold (mm). The statistics are over the points within the larger of
        /// this and 3.5 robust σ of the fitted shape (1.4826 × the residuals' median absolute
        /// deviation): gross outliers out, the scatter whole however wide.
        #[arg(long, default_value_t = 2.0, allow_negative_numbers = true)]
        inlier_mm: f64,
        /// RANSAC hypotheses (cylinder and cone use at most 24).
        #[arg(long, default_value_t = 200, allow_negative_numbers = true)]
        iterations: usize,
        /// Random seed (same seed, same result).
        #[arg(long, default_value_t = 1, allow_negative_numbers = true)]
        seed: u64,
        /// Nominal radius (mm), to report the fitted radius error, ± its standard error (a
        /// jackknife over 10 interleaved blocks of the points).
        #[arg(long, allow_negative_numbers = true)]
        radius: Option<f64>,
        /// Nominal sphere centre (mm), to report the centre distance error, ± its standard error.
        #[arg(long, value_name = "X,Y,Z", allow_hyphen_values = true)]
        centre: Option<String>,
        /// Print JSON instead of a table.
        #[arg(long)]
        json: bool,
        /// Move the cloud by this rigid transform first (transform.json, see `align`).
        #[arg(long)]
        transform: Option<PathBuf>,
        /// The cloud (PLY; `-` = stdin).
        cloud: PathBuf,
    },
    /// Signed distances to the true surfaces of a scene.json, per object.
    #[command(after_help = "Example:\n  omni-eval compare --scene scene.json cloud.ply")]
    Compare {
        /// The scene the cloud was measured in.
        #[arg(long)]
        scene: PathBuf,
        /// Points farther than this from every surface are counted as stray, not measured (mm).
        #[arg(long, default_value_t = 20.0, allow_negative_numbers = true)]
        max_distance_mm: f64,
        /// Inlier threshold of the radius/centre fits (mm).
        #[arg(long, default_value_t = 2.0, allow_negative_numbers = true)]
        inlier_mm: f64,
        /// Print the fit as one JSON object instead of a table.
        #[arg(long)]
        json: bool,
        /// Move the cloud by this rigid transform first (transform.json, see `align`).
        #[arg(long)]
        transform: Option<PathBuf>,
        /// The cloud (PLY; `-` = stdin).
        cloud: PathBuf,
    },
    /// Register a calibrated sensor's frame to a reference frame through the calibration rig:
    /// the rig boards as posed during light-plane calibration (scanner.json's report) against
    /// their known poses; writes transform.json (calibrated → reference).
    #[command(
        after_help = "Example:\n  omni-eval align --scanner scanner.json --reference-poses reference_poses.json --rig rig.json -o transform.json"
    )]
    Align {
        /// scanner.json written by omni-calib-plane (its report lists the board poses it used).
        #[arg(long)]
        scanner: PathBuf,
        /// The boards' known poses in the reference frame (omniscan.board_poses).
        #[arg(long)]
        reference_poses: PathBuf,
        /// The rig (omniscan.rig): gives each board's corner grid.
        #[arg(long)]
        rig: PathBuf,
        /// Output transform.json (`-` = stdout).
        #[arg(short, long, default_value = "-")]
        output: PathBuf,
    },
    /// Predict the per-point σ at each range from speckle, photon + read noise and calibration,
    /// for a matte wall facing the sensor (as the paper's plane), and their sum.
    #[command(after_help = "\
The optics come from camera.json's `optics` (omni-sim writes them), else the paper preset's lens
(F/4, 650 nm, 4.65 µm pixels); --f-number etc. override. The camera and laser photometry are the
virtual sensor's defaults. The calibration term needs the calibration reports that
omni-calib-receiver and omni-calib-plane write into camera.json and scanner.json.

Example:
  omni-eval budget --camera calib/camera.json --scanner calib/scanner.json --range 300:2000:100")]
    Budget {
        /// camera.json: the camera model, its optics and its calibration report.
        #[arg(long)]
        camera: PathBuf,
        /// scanner.json: the light planes and their calibration report.
        #[arg(long)]
        scanner: PathBuf,
        /// Wall distances (mm): start:stop:step (stop included) or a list a,b,c.
        #[arg(long, default_value = "300:2000:100", allow_hyphen_values = true)]
        range: String,
        /// Mirror angle of the light plane (degrees within the facet).
        #[arg(long, default_value_t = 20.0, allow_negative_numbers = true)]
        alpha_deg: f64,
        /// Albedo of the wall.
        #[arg(long, default_value_t = 0.8, allow_negative_numbers = true)]
        albedo: f64,
        /// Lens F-number.
        #[arg(long, allow_negative_numbers = true)]
        f_number: Option<f64>,
        /// Laser wavelength (nm).
        #[arg(long, allow_negative_numbers = true)]
        wavelength_nm: Option<f64>,
        /// Pixel pitch (µm).
        #[arg(long, allow_negative_numbers = true)]
        pixel_pitch_um: Option<f64>,
        /// Independent speckle patterns the camera averages (1–16; contrast 1/√N): 2 for a
        /// depolarising matte surface, more with a speckle reducer (a moving diffuser, several
        /// laser angles or wavelengths).
        #[arg(long)]
        speckle_patterns: Option<u32>,
        /// Machine-readable output (one JSON document).
        #[arg(long)]
        json: bool,
    },
    /// Draw a cloud as a PNG picture (a view from above-front, coloured by height).
    #[command(after_help = "Example:\n  omni-eval render --color range cloud.ply -o cloud.png")]
    Render {
        /// The cloud (PLY; `-` = stdin).
        cloud: PathBuf,
        /// Output PNG.
        #[arg(short, long)]
        output: PathBuf,
        /// Picture width (px, 16 to 16384); the height follows the cloud's extent (at most
        /// 4 × the width and 16384).
        #[arg(long, default_value_t = 800, value_parser = clap::value_parser!(u32).range(16..=16384), allow_negative_numbers = true)]
        width: u32,
        /// Colour by `height` (z) or `range` (distance from the world origin, not the viewpoint
        /// distance of the clouds' `scalar_range`).
        #[arg(long, default_value = "height")]
        color: omni_cloud::render::ColorBy,
    },
}

fn numbers(opt: &str, s: &str, n: usize) -> Result<Vec<f64>, CliError> {
    let v: Vec<f64> = s.split(',').filter_map(|t| t.trim().parse::<f64>().ok()).collect();
    if v.len() != n || s.split(',').count() != n || !v.iter().all(|x| x.is_finite()) {
        return Err(CliError::usage(format!("--{opt}: expected {n} comma-separated numbers, got {s:?}")));
    }
    Ok(v)
}

/// The cloud's positions (inside `crop` if given); an empty cloud is an error.
fn load_points(path: &Path, crop: Option<&CropBox>, transform: Option<&Path>) -> Result<Vec<Point3<f64>>, CliError> {
    let name = omni_formats::io::display_name(path, "stdin");
    let iso = match transform {
        Some(t) => {
            let file: TransformFile = read_doc(t)?;
            Some(file.isometry().map_err(|m| format!("{}: {m}", t.display()))?)
        }
        None => None,
    };
    let mut pts = Vec::new();
    omni_cloud::ply_stream::for_each_vertex(
        path,
        &mut |_, n| if n == 0 { Err(format!("{name}: the PLY has no vertices")) } else { Ok(()) },
        &mut |p, _| {
            let q = match &iso {
                Some(iso) => iso * Point3::from(*p),
                None => Point3::from(*p),
            };
            if crop.is_none_or(|b| b.contains(&[q.x, q.y, q.z])) {
                pts.push(q);
            }
            Ok(())
        },
    )?;
    if pts.is_empty() {
        return Err(CliError::new(format!("{name}: no points inside the crop box")));
    }
    Ok(pts)
}

/// `start:stop:step` (stop included) or `a,b,c`, in mm.
fn parse_ranges(s: &str) -> Result<Vec<f64>, CliError> {
    let bad = || CliError::usage(format!("--range: expected start:stop:step or a,b,c (mm), got {s:?}"));
    let v: Vec<f64> = if s.contains(':') {
        let p: Vec<f64> = s.split(':').map(|t| t.trim().parse::<f64>().map_err(|_| bad())).collect::<Result<_, _>>()?;
        let [a, b, step] = p[..] else { return Err(bad()) };
        if !(step > 0.0) || !(b >= a) {
            return Err(bad());
        }
        if (b - a) / step > 10_000.0 {
            return Err(CliError::usage(format!("--range {s}: more than 10000 ranges; take a longer step")));
        }
        let n = ((b - a) / step + 1e-9).floor() as usize;
        (0..=n).map(|i| a + step * i as f64).collect()
    } else {
        s.split(',').map(|t| t.trim().parse::<f64>().map_err(|_| bad())).collect::<Result<_, _>>()?
    };
    if v.is_empty() {
        return Err(bad());
    }
    if let Some(x) = v.iter().find(|x| !(x.is_finite() && **x > 0.0)) {
        return Err(CliError::usage(format!("--range {s}: ranges are positive distances (mm), got {x}")));
    }
    Ok(v)
}

fn print_budget(
    lines: &[omni_simulator::BudgetLine],
    optics: &omni_simulator::Optics,
    calibration: &omni_simulator::CalibrationUncertainty,
    json: bool,
) -> Result<(), CliError> {
    let mut out = std::io::stdout().lock();
    let io = omni_cli::stdout_error;
    if json {
        let doc = serde_json::json!({"format": "omniscan.budget", "version": 1, "optics": optics,
            "calibration": calibration, "lines": lines});
        writeln!(out, "{doc}").map_err(io)?;
        return Ok(());
    }
    writeln!(
        out,
        "# F/{} λ {} nm, pitch {} µm, speckle contrast {:.2}; σ per point (mm); calibration: camera {} px, planes {} mm",
        optics.f_number,
        optics.wavelength_nm,
        optics.pixel_pitch_um,
        optics.speckle_contrast(),
        calibration.camera_px.map_or("-".into(), |v| format!("{v:.4}")),
        calibration.planes_mm.map_or("-".into(), |v| format!("{v:.4}")),
    )
    .map_err(io)?;
    writeln!(
        out,
        "{:>8} {:>9} {:>9} {:>9} {:>9} {:>9} {:>9}",
        "range", "mm/px", "speckle", "noise", "calib", "total", "line px"
    )
    .map_err(io)?;
    for l in lines {
        let calib = l.calibration_mm.map_or("-".to_string(), |v| format!("{v:.3}"));
        writeln!(
            out,
            "{:>8.0} {:>9.2} {:>9.3} {:>9.3} {:>9} {:>9.3} {:>9.3}",
            l.range_mm, l.mm_per_px, l.speckle_mm, l.noise_mm, calib, l.total_mm, l.line_sigma_px
        )
        .map_err(io)?;
    }
    Ok(())
}

fn main() -> std::process::ExitCode {
    omni_cli::main("omni-eval", || match omni_cli::parse_args::<Args>()?.command {
        Command::Fit { shape, crop, inlier_mm, iterations, seed, radius, centre, json, transform, cloud } => {
            let crop = match crop {
                Some(s) => {
                    let v = numbers("crop", &s, 6)?;
                    Some(CropBox::new([v[0], v[1], v[2]], [v[3], v[4], v[5]]).map_err(CliError::usage)?)
                }
                None => None,
            };
            let centre = centre.map(|s| numbers("centre", &s, 3)).transpose()?.map(|v| Point3::new(v[0], v[1], v[2]));
            omni_cli::positive("--inlier-mm", inlier_mm)?;
            if iterations == 0 {
                return Err(CliError::usage("--iterations must be at least 1"));
            }
            if let Some(r) = radius {
                omni_cli::positive("--radius", r)?;
            }
            let pts = load_points(&cloud, crop.as_ref(), transform.as_deref())?;
            let name = omni_formats::io::display_name(&cloud, "stdin");
            let opts = FitOptions { inlier_mm, iterations, seed };
            let (fit, errors) =
                eval::fit_with_errors(shape, &pts, &opts, radius, centre).map_err(|m| format!("{name}: {m}"))?;
            let measured = Measured {
                points: pts.len(),
                stats: fit.stats,
                band_mm: fit.band_mm,
                radius_error: errors.radius,
                centre_error: errors.centre,
            };
            print_fit(&mut std::io::stdout().lock(), &fit.shape, &measured, json).map_err(omni_cli::stdout_error)?;
            Ok(())
        }
        Command::Compare { scene, max_distance_mm, inlier_mm, json, transform, cloud } => {
            omni_cli::positive("--max-distance-mm", max_distance_mm)?;
            omni_cli::positive("--inlier-mm", inlier_mm)?;
            let scene_file: SceneFile = read_doc(&scene)?;
            let pts = load_points(&cloud, None, transform.as_deref())?;
            let opts = FitOptions { inlier_mm, ..FitOptions::default() };
            let comparison = compare_with_scene(&scene_file, &pts, max_distance_mm, &opts)
                .map_err(|m| format!("{}: {m}", scene.display()))?;
            if !comparison.unmeasured.is_empty() {
                omni_cli::warn(
                    "omni-eval",
                    &format!(
                        "no point within --max-distance-mm {max_distance_mm} of {}: not measured",
                        comparison.unmeasured.join(", ")
                    ),
                );
            }
            print_compare(&mut std::io::stdout().lock(), &comparison, pts.len(), json)
                .map_err(omni_cli::stdout_error)?;
            Ok(())
        }
        Command::Align { scanner, reference_poses, rig, output } => {
            let (scanner_file, _) = omni_formats::ScannerFile::load(&scanner)?;
            let reference: BoardPosesFile = read_doc(&reference_poses)?;
            let rig_file: RigFile = read_doc(&rig)?;
            let used = scanner_file.report.as_ref().and_then(|r| r.get("boards")).cloned().ok_or_else(|| {
                format!("{}: field report.boards: missing (not written by omni-calib-plane?)", scanner.display())
            })?;
            // The report's entries carry more (source, corner residuals): keep the pose fields.
            let poses: Vec<serde_json::Value> = used
                .as_array()
                .map(|a| {
                    a.iter()
                        .map(|b| serde_json::json!({"board": b["board"], "rotation": b["rotation"], "translation_mm": b["translation_mm"]}))
                        .collect()
                })
                .unwrap_or_default();
            let used = BoardPosesFile::new(
                serde_json::from_value(serde_json::Value::Array(poses))
                    .map_err(|e| format!("{}: field report.boards: {e}", scanner.display()))?,
            );
            used.validate().map_err(|m| format!("{}: report.boards: {m}", scanner.display()))?;
            let (iso, rms) = omni_cloud::align::register_rig(&rig_file, &used.poses, &reference.poses)
                .map_err(|m| format!("{}: {m}", reference_poses.display()))?;
            let doc = TransformFile::from_isometry(
                &iso,
                Some(rms),
                "calibrated sensor frame -> reference frame, through the rig boards",
            );
            omni_formats::write_doc(&output, &doc)?;
            eprintln!("omni-eval: rig registration RMS {rms:.3} mm over {} boards", used.poses.len());
            Ok(())
        }
        Command::Budget {
            camera,
            scanner,
            range,
            alpha_deg,
            albedo,
            f_number,
            wavelength_nm,
            pixel_pitch_um,
            speckle_patterns,
            json,
        } => {
            let ranges = parse_ranges(&range)?;
            if !(albedo > 0.0 && albedo <= 1.0) {
                return Err(CliError::usage("--albedo must be within (0, 1]"));
            }
            if !alpha_deg.is_finite() {
                return Err(CliError::usage("--alpha-deg must be finite"));
            }
            let (camera_file, camera_model) = omni_formats::CameraFile::load(&camera)?;
            // The budget's photometry needs the laser's source, which a fixed plane does not record.
            let (scanner_file, transmitter) = omni_formats::ScannerFile::load_polygon(&scanner)?;
            let base = camera_file.optics.unwrap_or_else(omni_simulator::Optics::paper);
            let optics = omni_simulator::Optics {
                f_number: f_number.unwrap_or(base.f_number),
                wavelength_nm: wavelength_nm.unwrap_or(base.wavelength_nm),
                pixel_pitch_um: pixel_pitch_um.unwrap_or(base.pixel_pitch_um),
                speckle_patterns: speckle_patterns.unwrap_or(base.speckle_patterns),
                ..base
            };
            optics.validate().map_err(|e| CliError::usage(format!("optics: {e}")))?;
            let opts = omni_simulator::RenderOptions::default().with_optics(optics);
            let calibration =
                omni_simulator::calibration_from_reports(camera_file.report.as_ref(), scanner_file.report.as_ref());
            transmitter
                .check_alpha(alpha_deg.to_radians())
                .map_err(|e| CliError::usage(format!("--alpha-deg: {alpha_deg}° is {e}")))?;
            let sensor = omni_simulator::Sensor { camera: camera_model, transmitter };
            opts.check_sensor(&sensor).map_err(|e| CliError::new(format!("{}: {e}", camera.display())))?;
            let lines = omni_simulator::error_budget(
                &sensor,
                &optics,
                &opts,
                &calibration,
                albedo,
                alpha_deg.to_radians(),
                &ranges,
            );
            if lines.is_empty() {
                return Err(CliError::new(format!(
                    "no range in {range} is seen on the light plane at α = {alpha_deg}° (try other ranges or --alpha-deg)"
                )));
            }
            print_budget(&lines, &optics, &calibration, json)
        }
        Command::Render { cloud, output, width, color } => {
            let pts = load_points(&cloud, None, None)?;
            let img = omni_cloud::render::render(&pts, width, color);
            omni_formats::io::write_atomic(&output, |w| {
                let mut bytes = Vec::new();
                image::RgbImage::from_raw(img.width, img.height, img.rgb)
                    .ok_or_else(|| std::io::Error::other("image size"))?
                    .write_to(&mut std::io::Cursor::new(&mut bytes), image::ImageFormat::Png)
                    .map_err(std::io::Error::other)?;
                w.write_all(&bytes)
            })?;
            Ok(())
        }
    })
}

fn shape_json(s: &Shape) -> serde_json::Value {
    let v3 = |p: &[f64]| serde_json::json!([p[0], p[1], p[2]]);
    match s {
        Shape::Plane(p) => {
            serde_json::json!({"type": "plane", "normal": v3(p.normal.as_slice()), "offset_mm": p.offset})
        }
        Shape::Sphere { center, radius } => {
            serde_json::json!({"type": "sphere", "centre_mm": v3(center.coords.as_slice()), "radius_mm": radius})
        }
        Shape::Cylinder { axis_point, axis, radius } => serde_json::json!({"type": "cylinder",
            "axis_point_mm": v3(axis_point.coords.as_slice()), "axis": v3(axis.as_slice()), "radius_mm": radius}),
        Shape::Cone { apex, axis, half_angle } => serde_json::json!({"type": "cone",
            "apex_mm": v3(apex.coords.as_slice()), "axis": v3(axis.as_slice()), "half_angle_deg": half_angle.to_degrees()}),
    }
}

/// A fit's residual statistics and errors against the nominal shape.
struct Measured {
    /// Points given, and the statistics of those within `band_mm` of the shape.
    points: usize,
    stats: ErrorStats,
    band_mm: f64,
    /// Fitted − nominal radius and the centre's distance from the nominal one (mm), each with
    /// its jackknife standard error (mm) where the leave-outs allow one.
    radius_error: Option<(f64, Option<f64>)>,
    centre_error: Option<(f64, Option<f64>)>,
}

fn print_fit(out: &mut dyn Write, shape: &Shape, m: &Measured, json: bool) -> std::io::Result<()> {
    let e = &m.stats;
    if json {
        let mut v = serde_json::json!({"shape": shape_json(shape), "points": m.points, "inliers": e.count,
            "band_mm": m.band_mm, "errors": e});
        if let Some((r, se)) = m.radius_error {
            v["radius_error_mm"] = r.into();
            v["radius_error_se_mm"] = se.into();
        }
        if let Some((c, se)) = m.centre_error {
            v["centre_error_mm"] = c.into();
            v["centre_error_se_mm"] = se.into();
        }
        writeln!(out, "{v}")?;
        return Ok(());
    }
    let v = shape_json(shape);
    writeln!(out, "shape               {}", v["type"].as_str().unwrap_or("?"))?;
    if let Some(obj) = v.as_object() {
        for (k, val) in obj.iter().filter(|(k, _)| k.as_str() != "type") {
            writeln!(out, "{k:<20}{}", rounded(val))?;
        }
    }
    writeln!(
        out,
        "points              {} ({} within {:.3} mm of the shape, {:.1} %)",
        m.points,
        e.count,
        m.band_mm,
        100.0 * e.count as f64 / m.points as f64
    )?;
    print_stats(out, e)?;
    let se = |se: Option<f64>| se.map_or(String::new(), |s| format!(" ± {s:.4}"));
    if let Some((r, s)) = m.radius_error {
        writeln!(out, "radius error        {r:+.4}{} mm", se(s))?;
    }
    if let Some((c, s)) = m.centre_error {
        writeln!(out, "centre error        {c:.4}{} mm", se(s))?;
    }
    Ok(())
}

/// A shape parameter as the table prints it: numbers to 6 decimals (nm in mm, µ° in degrees),
/// beyond any fit's precision; arrays element by element.
fn rounded(v: &serde_json::Value) -> String {
    match v {
        serde_json::Value::Number(n) => n.as_f64().map_or(n.to_string(), |x| format!("{x:.6}")),
        serde_json::Value::Array(a) => format!("[{}]", a.iter().map(rounded).collect::<Vec<_>>().join(", ")),
        other => other.to_string(),
    }
}

fn print_stats(out: &mut dyn Write, e: &ErrorStats) -> std::io::Result<()> {
    writeln!(out, "mean signed error   {:+.4} mm", e.mean)?;
    writeln!(out, "standard deviation  {:.4} mm", e.std_dev)?;
    writeln!(out, "rms                 {:.4} mm", e.rms)?;
    writeln!(out, "max |error|         {:.4} mm", e.max_abs)?;
    Ok(())
}

fn print_compare(out: &mut dyn Write, c: &Comparison, n: usize, json: bool) -> std::io::Result<()> {
    if json {
        let v =
            serde_json::json!({"points": n, "stray_points": c.stray, "objects": c.objects, "unmeasured": c.unmeasured});
        writeln!(out, "{v}")?;
        return Ok(());
    }
    writeln!(
        out,
        "{:<14}{:<10}{:>8}{:>11}{:>10}{:>10}{:>10}{:>20}{:>20}",
        "object", "kind", "points", "mean mm", "std mm", "rms mm", "max mm", "radius err mm", "centre err mm"
    )?;
    // An error with its standard error (the jackknife's), to the precision it has.
    let with_se = |x: Option<f64>, se: Option<f64>, signed: bool| match (x, se) {
        (Some(v), Some(se)) if signed => format!("{v:+.3} ± {se:.3}"),
        (Some(v), Some(se)) => format!("{v:.3} ± {se:.3}"),
        (Some(v), None) if signed => format!("{v:+.3}"),
        (Some(v), None) => format!("{v:.3}"),
        (None, _) => "-".to_string(),
    };
    for r in &c.objects {
        let e = &r.errors;
        writeln!(
            out,
            "{:<14}{:<10}{:>8}{:>+11.4}{:>10.4}{:>10.4}{:>10.4}{:>20}{:>20}",
            r.name,
            r.kind,
            e.count,
            e.mean,
            e.std_dev,
            e.rms,
            e.max_abs,
            with_se(r.radius_error_mm, r.radius_error_se_mm, true),
            with_se(r.centre_error_mm, r.centre_error_se_mm, false)
        )?;
    }
    for name in &c.unmeasured {
        writeln!(out, "{name:<14}{:<10}{:>8}   (not measured: no point near it)", "-", 0)?;
    }
    writeln!(out, "{n} points, {} farther than the distance limit from every surface", c.stray)?;
    Ok(())
}
