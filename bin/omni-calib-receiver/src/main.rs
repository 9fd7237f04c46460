//! omni-calib-receiver: calibrate the catadioptric camera from checkerboard images.

use clap::{Parser, Subcommand};
use omni_calib::receiver::corners_file::{CornersFile, ImageCorners};
use omni_calib::receiver::{self, Calibration, ModelKind, Observation, Options, export};
use omni_cli::{CliError, CliResult};
use omni_formats::{BoardFile, CameraFile, CameraSpec, read_doc, write_doc};
use omni_vision::corners::{DetectorOptions, GrayF32, detect_board, load_gray, overlay};
use omni_vision::rim;
use rayon::prelude::*;
use std::io::{BufRead as _, Write as _};
use std::path::{Path, PathBuf};

#[derive(Parser, Debug)]
#[command(
    // Help is printed as written, unwrapped: examples stay one line for copy and paste.
    term_width = 0,
    version,
    about = "Calibrate the catadioptric camera (receiver) from checkerboard images: detect the corners, \
fit a camera model, write camera.json with the fitted model and a report.",
    args_conflicts_with_subcommands = true,
    subcommand_negates_reqs = true,
    after_help = "Examples:\n  \
omni-calib-receiver --board board.json -o camera.json boards/*.png\n  \
omni-calib-receiver --board board.json --model ocam --export-ocam calib_results.txt boards/\n  \
omni-calib-receiver --board board.json --save-corners corners.json --overlay check/ boards/\n  \
omni-calib-receiver --board board.json --corners corners.json --model mei --export-kalibr camchain.yaml\n  \
omni-calib-receiver --board board.json --annulus 511.5,511.5,102.5,493 boards/\n  \
omni-calib-receiver --board board.json --annulus auto boards/\n  \
omni-calib-receiver --board board.json --rim-image lit_room.png boards/\n  \
omni-calib-receiver find-annulus pose.png        (prints CX,CY,R_IN,R_OUT for --annulus)\n  \
omni-calib-receiver import-ocam calib_results.txt -o camera.json\n  \
omni-calib-receiver export camera.json --to opencv -o omnidir.yaml\n  \
omni-calib-receiver convert camera.json --to ocam -o ocam.json     (fits OCamCalib's model to the rays)\n  \
omni-calib-receiver import-kalibr camchain.yaml -o camera.json\n  \
omni-calib-receiver import-opencv omnidir.yaml -o camera.json\n  \
omni-calib-receiver query --camera camera.json < questions.txt     (lines \"u v\" → rays, \"x y z\" → pixels)\n\n\
Models: mei (unified sphere model + radial-tangential distortion, as Kalibr omni-radtan and OpenCV \
omnidir), ocam (Scaramuzza polynomial, as OCamCalib), hyperbolic (the exact mirror of --mirror with \
focal length and principal point fitted). Images may be files or directories (png, jpg, tif). \
Images whose board is not found, has too few corners, or fits much worse than the others are \
reported and left out. camera.json is written only if the calibration succeeded.\n\
Exported Kalibr and OpenCV files describe the unit sphere (x, y, −z) of the omniscan world about \
the viewpoint (written into the files as a comment; see docs/FORMATS.md).\n\
Exit codes: 0 ok, 1 bad input or failed calibration, 2 usage error."
)]
struct Args {
    #[command(subcommand)]
    command: Option<Command>,
    #[command(flatten)]
    calib: CalibArgs,
}

#[derive(clap::Args, Debug)]
struct CalibArgs {
    /// The checkerboard (board.json: inner corners and square size).
    #[arg(long, required = true)]
    board: Option<PathBuf>,
    /// Camera model to fit: mei, ocam or hyperbolic.
    #[arg(long, default_value = "mei")]
    model: ModelKind,
    /// Read corners from this file (see --save-corners) instead of detecting them.
    #[arg(long, conflicts_with = "images")]
    corners: Option<PathBuf>,
    /// Write the detected corners to this file (JSON, `omniscan.corners`).
    #[arg(long)]
    save_corners: Option<PathBuf>,
    /// Write one PNG per image with detected (green) and reprojected (red) corners here.
    #[arg(long, value_name = "DIR")]
    overlay: Option<PathBuf>,
    /// Output camera.json (`-` = stdout).
    #[arg(short, long, default_value = "camera.json")]
    output: PathBuf,
    /// For --model hyperbolic: camera.json of kind hyperbolic giving the mirror (a, b, rim);
    /// default: the paper's mirror.
    #[arg(long)]
    mirror: Option<PathBuf>,
    /// For --model hyperbolic: also fit the camera's offset from the mirror's focus and its tilt
    /// (a non-central model; for a camera off the focus, which the model check warns about).
    #[arg(long)]
    non_central: bool,
    /// Also export OCamCalib calib_results.txt (needs --model ocam).
    #[arg(long, value_name = "FILE")]
    export_ocam: Option<PathBuf>,
    /// Also export Kalibr camchain.yaml, omni + radtan (needs --model mei).
    #[arg(long, value_name = "FILE")]
    export_kalibr: Option<PathBuf>,
    /// Also export OpenCV omnidir K, D, xi as OpenCV YAML (needs --model mei).
    #[arg(long, value_name = "FILE")]
    export_opencv: Option<PathBuf>,
    /// The image topic written into --export-kalibr's camchain.yaml (`rostopic`).
    #[arg(long, value_name = "TOPIC", default_value = export::DEFAULT_ROSTOPIC)]
    rostopic: String,
    /// Also report a held-out test RMS: K-fold validation (each K-th image posed under the model
    /// fitted to the others; K more fits). 0 = none.
    #[arg(long, value_name = "K", default_value_t = 0)]
    folds: usize,
    /// Huber threshold of the robust loss (px).
    #[arg(long, default_value_t = 1.0, allow_negative_numbers = true)]
    huber_px: f64,
    /// Where the fitted model's single viewpoint sits in the world frame (mm). Board images fix
    /// the rays' directions, not the origin: 0,0,0 makes the viewpoint the origin; the mirror's
    /// focus 0,0,2c (0,0,80 for the paper's mirror) keeps SENSOR.md's frame, origin at the camera.
    #[arg(long, value_name = "X,Y,Z", default_value = "0,0,0", allow_hyphen_values = true)]
    viewpoint_mm: String,
    /// The mirror annulus in the image (px): centre x, centre y, inner and outer rim radius, as
    /// read off an image of a lit scene; or `auto`: found in the board images themselves (the
    /// rim circle of their per-pixel range: the mirror is where the content changed). Corners are
    /// searched inside it and dropped where their refinement window reaches a rim (the rim edge
    /// biases them); the principal point starts at its centre; the fitted mei/ocam model is
    /// valid inside it. The annulus used is printed and written into the report. Default: the
    /// whole image.
    #[arg(long, value_name = "CX,CY,R_IN,R_OUT|auto", conflicts_with = "rim_image", allow_hyphen_values = true)]
    annulus: Option<String>,
    /// Find the annulus (outer mirror rim and, if visible, the blind centre) in this image of a
    /// lit scene (same camera and size as the board images) instead of giving --annulus.
    #[arg(long, value_name = "FILE")]
    rim_image: Option<PathBuf>,
    /// Board images (files or directories).
    #[arg(required_unless_present = "corners")]
    images: Vec<PathBuf>,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Find the mirror annulus (outer rim and, if visible, blind centre) in an image of a lit
    /// scene, or in the per-pixel range of several images (e.g. the board images), and print it
    /// as CX,CY,R_IN,R_OUT (px) for --annulus. Exit 1 with the reason if no rim circle is found.
    FindAnnulus {
        /// One lit image, or several images / directories of one camera.
        #[arg(required = true)]
        images: Vec<PathBuf>,
    },
    /// Convert an OCamCalib calib_results.txt into camera.json (kind ocam). The centre's pixel
    /// origin is read from its header: OCamCalib v3 ("starting from 0 (C convention)") as
    /// written, older files (Matlab, 1-based) minus one.
    ImportOcam {
        /// OCamCalib's calib_results.txt (`-` = stdin).
        input: PathBuf,
        /// Output camera.json (`-` = stdout).
        #[arg(short, long, default_value = "camera.json")]
        output: PathBuf,
    },
    /// Ask a calibration: pixels give world rays, 3-D points give pixels. One question per line:
    /// `u v` (pixel) or `x y z` (point, mm, world frame), or JSON `[u, v]`, `[x, y, z]`,
    /// `{"px": [u, v]}`, `{"point_mm": [x, y, z]}`. A text answer repeats the question, then
    /// `ox oy oz dx dy dz` (ray origin in mm, unit direction) or `u v`, or `none` where the
    /// mirror does not see it; --json answers with one object per line.
    /// Example: echo "600 240" | omni-calib-receiver query --camera camera.json
    Query {
        /// The calibration (camera.json).
        #[arg(long)]
        camera: PathBuf,
        /// Questions (`-` = stdin).
        #[arg(short, long, default_value = "-")]
        input: PathBuf,
        /// Answers (`-` = stdout).
        #[arg(short, long, default_value = "-")]
        output: PathBuf,
        /// Answer in JSON (one object per line) instead of text.
        #[arg(long)]
        json: bool,
    },
    /// Write an existing camera.json in another tool's format without re-fitting: ocam
    /// (OCamCalib calib_results.txt, from kind ocam), kalibr (camchain.yaml) or opencv
    /// (cv::omnidir YAML), both from kind mei.
    Export {
        /// The calibration (camera.json).
        camera: PathBuf,
        /// Target format: ocam, kalibr or opencv.
        #[arg(long, value_parser = ["ocam", "kalibr", "opencv"])]
        to: String,
        /// For kalibr: the image topic (`rostopic`).
        #[arg(long, value_name = "TOPIC", default_value = export::DEFAULT_ROSTOPIC)]
        rostopic: String,
        /// Output file (`-` = stdout).
        #[arg(short, long)]
        output: PathBuf,
    },
    /// Convert a calibration into another model without a re-fit to boards: the target model is
    /// fitted to the source's rays over its mirror annulus. Prints the largest ray (deg) and
    /// pixel (px) difference and refuses (exit 1, no output) beyond the tolerances.
    Convert {
        /// The calibration (camera.json).
        camera: PathBuf,
        /// Target model: mei, ocam or hyperbolic.
        #[arg(long)]
        to: ModelKind,
        /// For --to hyperbolic: camera.json of kind hyperbolic giving the mirror (a, b, rim);
        /// default: the source's mirror if it is hyperbolic, else the paper's.
        #[arg(long)]
        mirror: Option<PathBuf>,
        /// Largest ray difference accepted (deg).
        #[arg(long, default_value_t = 0.05)]
        max_ray_deg: f64,
        /// Largest pixel difference accepted (px).
        #[arg(long, default_value_t = 0.2)]
        max_pixel_px: f64,
        /// Output camera.json (`-` = stdout).
        #[arg(short, long, default_value = "camera.json")]
        output: PathBuf,
    },
    /// Convert one camera of a Kalibr camchain.yaml (omni + radtan) into camera.json (kind mei).
    /// Kalibr's sphere (x, y, z) is (x, y, −z) of the omniscan world; the numbers are the same.
    ImportKalibr {
        /// Kalibr's camchain.yaml (`-` = stdin).
        input: PathBuf,
        /// Which camera of the chain.
        #[arg(long, default_value = "cam0")]
        cam: String,
        /// Output camera.json (`-` = stdout).
        #[arg(short, long, default_value = "camera.json")]
        output: PathBuf,
    },
    /// Convert an OpenCV cv::omnidir YAML file (K, D, xi, image_width, image_height) into
    /// camera.json (kind mei). OpenCV's sphere (x, y, z) is (x, y, −z) of the omniscan world.
    ImportOpencv {
        /// The OpenCV FileStorage YAML file (`-` = stdin).
        input: PathBuf,
        /// Output camera.json (`-` = stdout).
        #[arg(short, long, default_value = "camera.json")]
        output: PathBuf,
    },
}

fn main() -> std::process::ExitCode {
    omni_cli::main("omni-calib-receiver", || {
        let args = Args::parse();
        match args.command {
            Some(Command::ImportOcam { input, output }) => import_ocam(&input, &output),
            Some(Command::Query { camera, input, output, json }) => query(&camera, &input, &output, json),
            Some(Command::Export { camera, to, rostopic, output }) => export_camera(&camera, &to, &rostopic, &output),
            Some(Command::Convert { camera, to, mirror, max_ray_deg, max_pixel_px, output }) => {
                convert(&camera, to, mirror.as_deref(), [max_ray_deg, max_pixel_px], &output)
            }
            Some(Command::ImportKalibr { input, cam, output }) => {
                import_mei(&input, &output, "kalibr", |t| export::parse_kalibr_camchain(t, &cam))
            }
            Some(Command::ImportOpencv { input, output }) => {
                import_mei(&input, &output, "opencv-omnidir", export::parse_opencv_omnidir)
            }
            Some(Command::FindAnnulus { images }) => find_annulus(&expand_images(&images)?),
            None => calibrate(&args.calib),
        }
    })
}

fn parse_annulus(s: &str) -> CliResult<[f64; 4]> {
    let v: Vec<f64> = s.split(',').filter_map(|t| t.trim().parse().ok()).collect();
    match v[..] {
        [cx, cy, r0, r1]
            if v.iter().all(|c: &f64| c.is_finite()) && s.split(',').count() == 4 && r0 >= 0.0 && r0 < r1 =>
        {
            Ok([cx, cy, r0, r1])
        }
        _ => Err(omni_cli::CliError::usage(format!(
            "--annulus: expected CX,CY,R_IN,R_OUT in px with 0 ≤ R_IN < R_OUT, got {s:?}"
        ))),
    }
}

/// Where a detected annulus came from: the image's size (to check against the board images) and
/// its name for messages.
type RimSource = (usize, usize, String);

/// The annulus to use, from `--annulus CX,CY,R_IN,R_OUT`, `--annulus auto` (the rim circle of the
/// board images' range image) or `--rim-image FILE`; with its source if it was detected.
fn resolve_annulus(args: &CalibArgs, boards: &[PathBuf]) -> CliResult<Option<([f64; 4], Option<RimSource>)>> {
    let (img, source) = match (args.annulus.as_deref(), &args.rim_image) {
        (None, None) => return Ok(None),
        (Some("auto"), _) => {
            if boards.is_empty() {
                return Err(CliError::usage(
                    "--annulus auto needs board images (not --corners); give --rim-image or numbers",
                ));
            }
            (rim_input(boards)?, "--annulus auto (board images)".to_string())
        }
        (Some(numbers), _) => {
            return Ok(Some((parse_annulus(numbers)?, None)));
        }
        (None, Some(path)) => (load_gray(path)?, path.display().to_string()),
    };
    let a = detect_annulus(&img, &source)?;
    Ok(Some((a, Some((img.width, img.height, source)))))
}

/// One image as it is, several as their per-pixel range or the best single one ([`rim::rim_image`]).
fn rim_input(paths: &[PathBuf]) -> CliResult<GrayF32> {
    let images: Vec<GrayF32> = paths.par_iter().map(|p| load_gray(p)).collect::<Result<_, _>>()?;
    if let Some(k) = images.iter().position(|i| (i.width, i.height) != (images[0].width, images[0].height)) {
        return Err(CliError::new(format!(
            "{}: image is {} × {} px but {} is {} × {} px (all images must come from one camera)",
            paths[k].display(),
            images[k].width,
            images[k].height,
            paths[0].display(),
            images[0].width,
            images[0].height
        )));
    }
    let name = |k: usize| paths[k].display().to_string();
    let source = if paths.len() == 1 { name(0) } else { format!("{} images", paths.len()) };
    let chosen = rim::rim_image(&images, &rim::RimOptions::default()).map_err(|e| format!("{source}: {e}"))?;
    if let (rim::RimSource::Single(k), Some(why)) = (chosen.source, &chosen.range_error) {
        eprintln!("the range of the {source} shows no mirror rim ({why}); using the best single image, {}", name(k));
    }
    Ok(chosen.image)
}

/// The annulus of [`rim::detect_rim`], reported on stderr; errors name `source`.
fn detect_annulus(img: &GrayF32, source: &str) -> CliResult<[f64; 4]> {
    let found = rim::detect_rim(img, &rim::RimOptions::default()).map_err(|e| format!("{source}: {e}"))?;
    let a = found.annulus();
    eprintln!(
        "mirror annulus from {source}: centre ({:.2}, {:.2}) px, radii {:.2}–{:.2} px (rim fit RMS {:.3} px, {:.0} % of the rays{})",
        a[0],
        a[1],
        a[2],
        a[3],
        found.outer.rms_px,
        100.0 * found.outer.support,
        if found.inner.is_some() { "" } else { "; no blind-centre circle" }
    );
    Ok(a)
}

fn find_annulus(paths: &[PathBuf]) -> CliResult {
    let img = rim_input(paths)?;
    let source = match paths {
        [one] => one.display().to_string(),
        _ => format!("{} images", paths.len()),
    };
    let a = detect_annulus(&img, &source)?;
    // Through an io error, not println!: a closed stdout is a clean exit, not a panic.
    writeln!(std::io::stdout(), "{:.3},{:.3},{:.3},{:.3}", a[0], a[1], a[2], a[3])?;
    Ok(())
}

fn parse_viewpoint(s: &str) -> CliResult<[f64; 3]> {
    let v: Vec<f64> = s.split(',').filter_map(|t| t.trim().parse().ok()).collect();
    match v[..] {
        [x, y, z] if v.iter().all(|c: &f64| c.is_finite()) && s.split(',').count() == 3 => Ok([x, y, z]),
        _ => Err(omni_cli::CliError::usage(format!("--viewpoint-mm: expected X,Y,Z in mm, got {s:?}"))),
    }
}

/// Places the generic model's viewpoint (the exact hyperbolic model has its own, at 2c).
fn set_viewpoint(spec: &mut CameraSpec, viewpoint: [f64; 3]) {
    match spec {
        CameraSpec::Mei(p) => p.viewpoint_mm = viewpoint,
        CameraSpec::Ocam(p) => p.viewpoint_mm = viewpoint,
        CameraSpec::Hyperbolic(_) => {}
    }
}

/// The text of an input file (`-` = stdin) and its name for messages.
fn read_text(input: &Path) -> CliResult<(String, String)> {
    let name = omni_formats::io::display_name(input, "stdin");
    let bytes = omni_formats::io::read_all(input)?;
    let text = String::from_utf8(bytes).map_err(|_| format!("{name}: not UTF-8 text"))?;
    Ok((text, name))
}

fn import_ocam(input: &Path, output: &Path) -> CliResult {
    let (text, name) = read_text(input)?;
    let (params, origin) = export::parse_ocam_calib_results(&text).map_err(|e| format!("{name}: {e}"))?;
    let mut file = CameraFile::new(CameraSpec::Ocam(params));
    file.report = Some(serde_json::json!({"imported_from": name, "centre": origin.describe()}));
    write_doc(output, &file)?;
    Ok(())
}

/// Answers the questions of `input` line by line (so a pipe gets each answer as it asks).
fn query(camera: &Path, input: &Path, output: &Path, as_json: bool) -> CliResult {
    let (_, cam) = CameraFile::load(camera)?;
    let name = omni_formats::io::display_name(input, "stdin");
    let reader = omni_formats::io::open_input(input)?;
    let mut failure: Option<String> = None;
    omni_formats::io::write_atomic(output, |w| {
        for (n, line) in reader.lines().enumerate() {
            let line = line?;
            match receiver::query::parse_query(&line) {
                Ok(None) => {}
                Ok(Some(q)) => {
                    writeln!(w, "{}", receiver::query::answer(cam.as_ref(), q, as_json))?;
                    if output == Path::new("-") {
                        w.flush()?;
                    }
                }
                Err(e) => {
                    failure = Some(format!("{name}: line {}: {e}", n + 1));
                    // Abandons a file output (its temporary is removed); stdout keeps the answers so far.
                    return Err(std::io::Error::other("bad input"));
                }
            }
        }
        Ok(())
    })
    .map_err(|e| failure.take().map_or_else(|| CliError::from(e), CliError::new))
}

fn read_mirror(path: &Path) -> CliResult<omni_model::HyperbolicParams> {
    match read_doc::<CameraFile>(path)?.model {
        CameraSpec::Hyperbolic(h) => Ok(h),
        _ => Err(CliError::new(format!("{}: --mirror needs a camera of kind hyperbolic", path.display()))),
    }
}

fn convert(camera: &Path, to: ModelKind, mirror: Option<&Path>, limits: [f64; 2], output: &Path) -> CliResult {
    let source: CameraFile = read_doc(camera)?;
    let mirror = match (mirror, &source.model) {
        (Some(p), _) => read_mirror(p)?,
        (None, CameraSpec::Hyperbolic(h)) => h.clone(),
        (None, _) => omni_model::HyperbolicParams::paper(),
    };
    let c = receiver::convert::convert(&source.model, to, &mirror).map_err(|e| format!("{}: {e}", camera.display()))?;
    eprintln!(
        "converted to {to:?} over {} pixels of the annulus: rays within {:.4}°, pixels within {:.4} px",
        c.samples, c.max_ray_deg, c.max_pixel_px
    );
    if !(c.max_ray_deg <= limits[0] && c.max_pixel_px <= limits[1]) {
        return Err(CliError::new(format!(
            "{}: the {to:?} model differs from the source by up to {:.4}° / {:.4} px (limits --max-ray-deg {} / --max-pixel-px {}); not written",
            camera.display(),
            c.max_ray_deg,
            c.max_pixel_px,
            limits[0],
            limits[1]
        )));
    }
    let mut file = CameraFile::new(c.spec);
    file.report = Some(serde_json::json!({
        "converted_from": camera.display().to_string(),
        "max_ray_difference_deg": c.max_ray_deg,
        "max_pixel_difference_px": c.max_pixel_px,
        "pixels_compared": c.samples,
    }));
    write_doc(output, &file)?;
    Ok(())
}

fn export_camera(camera: &Path, to: &str, rostopic: &str, output: &Path) -> CliResult {
    let file: CameraFile = read_doc(camera)?;
    let text = match (to, &file.model) {
        ("ocam", CameraSpec::Ocam(p)) => {
            let (text, fit) = export::ocam_calib_results(p);
            report_inverse_fit(&fit);
            text
        }
        ("kalibr", CameraSpec::Mei(p)) => export::kalibr_camchain(p, rostopic),
        ("opencv", CameraSpec::Mei(p)) => export::opencv_omnidir_yaml(p),
        (to, model) => {
            let kind = match model {
                CameraSpec::Mei(_) => "mei",
                CameraSpec::Ocam(_) => "ocam",
                CameraSpec::Hyperbolic(_) => "hyperbolic",
            };
            let needs = if to == "ocam" { "ocam" } else { "mei" };
            return Err(CliError::new(format!(
                "{}: --to {to} needs a camera of kind {needs}, this one is {kind}",
                camera.display()
            )));
        }
    };
    write_text(output, &text)
}

fn report_inverse_fit(fit: &omni_model::ocam::InverseFit) {
    eprintln!(
        "OCamCalib inverse polynomial: degree {}, within {:.4} px of the direct one over radii {:.1}–{:.1} px",
        fit.degree, fit.max_error_px, fit.rho_range_px[0], fit.rho_range_px[1]
    );
}

/// Imports a Mei-model file (Kalibr, OpenCV) with `parse`; `kind` names the source format.
fn import_mei(
    input: &Path,
    output: &Path,
    kind: &str,
    parse: impl Fn(&str) -> Result<omni_model::MeiParams, String>,
) -> CliResult {
    let (text, name) = read_text(input)?;
    let params = parse(&text).map_err(|e| format!("{name}: {e}"))?;
    let mut file = CameraFile::new(CameraSpec::Mei(params));
    file.report = Some(serde_json::json!({"imported_from": name, "source_format": kind, "frame": export::FRAME_NOTE}));
    write_doc(output, &file)?;
    Ok(())
}

/// Image files named on the command line, directories expanded (sorted by name).
fn expand_images(paths: &[PathBuf]) -> CliResult<Vec<PathBuf>> {
    let mut out = Vec::new();
    for p in paths {
        if p.is_dir() {
            let mut files: Vec<PathBuf> = std::fs::read_dir(p)
                .map_err(|e| format!("{}: {e}", p.display()))?
                .filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|f| {
                    let ext = f.extension().and_then(|e| e.to_str()).unwrap_or("").to_ascii_lowercase();
                    matches!(ext.as_str(), "png" | "jpg" | "jpeg" | "tif" | "tiff" | "bmp" | "pgm")
                })
                .collect();
            files.sort();
            if files.is_empty() {
                return Err(CliError::new(format!("{}: no images in directory", p.display())));
            }
            out.extend(files);
        } else {
            out.push(p.clone());
        }
    }
    Ok(out)
}

fn check_exports(args: &CalibArgs) -> CliResult {
    if args.export_ocam.is_some() && args.model != ModelKind::Ocam {
        return Err(CliError::usage("--export-ocam needs --model ocam"));
    }
    if (args.export_kalibr.is_some() || args.export_opencv.is_some()) && args.model != ModelKind::Mei {
        return Err(CliError::usage("--export-kalibr and --export-opencv need --model mei"));
    }
    if !(args.huber_px.is_finite() && args.huber_px > 0.0) {
        return Err(CliError::usage("--huber-px must be a positive number"));
    }
    Ok(())
}

/// Detected corners and the images (kept for the overlays).
struct Detected {
    corners: CornersFile,
    images: Vec<Option<GrayF32>>,
}

fn detect(paths: &[PathBuf], board: &BoardFile, annulus: Option<[f64; 4]>, keep_images: bool) -> CliResult<Detected> {
    let detector = DetectorOptions { annulus, ..Default::default() };
    let bar = omni_cli::progress(Some(paths.len() as u64), "detecting corners");
    let results: Vec<Result<(GrayF32, ImageCorners), String>> = paths
        .par_iter()
        .map(|p| {
            let img = load_gray(p)?;
            let name = p.display().to_string();
            let found = detect_board(&img, board.inner_cols, board.inner_rows, &detector);
            bar.inc(1);
            let entry = ImageCorners::from_detection(name, found);
            Ok((img, entry))
        })
        .collect();
    bar.finish_and_clear();
    let mut size: Option<(usize, usize, String)> = None;
    let mut file = CornersFile::new(0, 0, board.inner_cols, board.inner_rows);
    let mut images = Vec::new();
    for r in results {
        let (img, entry) = r.map_err(CliError::new)?;
        match &size {
            None => size = Some((img.width, img.height, entry.name.clone())),
            Some((w, h, first)) if (*w, *h) != (img.width, img.height) => {
                return Err(CliError::new(format!(
                    "{}: image is {} × {} px but {first} is {w} × {h} px (all images must come from one camera)",
                    entry.name, img.width, img.height
                )));
            }
            _ => {}
        }
        file.images.push(entry);
        images.push(keep_images.then_some(img));
    }
    let (w, h, _) = size.ok_or_else(|| CliError::new("no images given"))?;
    file.width = w as u32;
    file.height = h as u32;
    Ok(Detected { corners: file, images })
}

fn load_corners(path: &Path, board: &BoardFile) -> CliResult<CornersFile> {
    let file: CornersFile = read_doc(path)?;
    file.validate().map_err(|e| format!("{}: {e}", path.display()))?;
    if (file.inner_cols, file.inner_rows) != (board.inner_cols, board.inner_rows) {
        return Err(CliError::new(format!(
            "{}: corners are for a {} × {} board but the board file says {} × {}",
            path.display(),
            file.inner_cols,
            file.inner_rows,
            board.inner_cols,
            board.inner_rows
        )));
    }
    Ok(file)
}

fn calibrate(args: &CalibArgs) -> CliResult {
    check_exports(args)?;
    let board_path = args.board.as_ref().ok_or_else(|| CliError::usage("--board is required"))?;
    let board: BoardFile = read_doc(board_path)?;
    board.validate().map_err(|e| format!("{}: {e}", board_path.display()))?;
    let mirror = match &args.mirror {
        Some(p) => read_mirror(p)?,
        None => omni_model::HyperbolicParams::paper(),
    };
    let paths = if args.corners.is_some() { Vec::new() } else { expand_images(&args.images)? };
    let annulus = resolve_annulus(args, &paths)?;
    let detected = match &args.corners {
        Some(path) => Detected { corners: load_corners(path, &board)?, images: Vec::new() },
        None => detect(&paths, &board, annulus.as_ref().map(|a| a.0), args.overlay.is_some())?,
    };
    if let Some((_, Some((rim_w, rim_h, rim_source)))) = &annulus
        && (*rim_w, *rim_h) != (detected.corners.width as usize, detected.corners.height as usize)
    {
        return Err(CliError::new(format!(
            "{rim_source}: image is {rim_w} × {rim_h} px but the board images are {} × {} px",
            detected.corners.width, detected.corners.height
        )));
    }
    let annulus = annulus.map(|a| a.0);
    if let Some(path) = &args.save_corners {
        write_doc(path, &detected.corners)?;
    }
    let corners = &detected.corners;
    let obs = corners.observations(board.square_mm);
    let opts = Options {
        model: args.model,
        huber_px: args.huber_px,
        mirror,
        annulus,
        non_central: args.non_central,
        ..Default::default()
    };
    let mut cal = receiver::calibrate(corners.width, corners.height, &obs, &opts).map_err(|e| {
        let reasons: Vec<String> =
            corners.images.iter().filter_map(|i| i.reason.as_ref().map(|r| format!("{}: {r}", i.name))).collect();
        CliError::new(format!("calibration failed: {e}; {}", reasons.join("; ")))
    })?;
    // The detector's reason ("no board found", …) says more than "too few corners (0 < 8)".
    for (img, entry) in cal.images.iter_mut().zip(&corners.images) {
        if entry.reason.is_some() {
            img.reason = entry.reason.clone();
        }
    }
    print_summary(&cal);
    let warnings: Vec<String> =
        corners.board_size_warning().into_iter().chain(receiver::validate::warnings(&cal, &opts)).collect();
    for w in &warnings {
        omni_cli::warn("omni-calib-receiver", w);
    }
    let held_out = match args.folds {
        0 => None,
        k => {
            let h = receiver::validate::k_fold(corners.width, corners.height, &obs, &opts, k)?;
            eprintln!(
                "held-out RMS per corner ({k}-fold, {} corners): test {:.3} px, training {:.3} px",
                h.test_corners, h.test_rms_px, h.train_rms_px
            );
            Some(h)
        }
    };
    if let Some(dir) = &args.overlay {
        write_overlays(dir, &cal, &obs, &detected)?;
    }
    write_exports(args, &cal)?;
    let mut spec = cal.spec.clone();
    set_viewpoint(&mut spec, parse_viewpoint(&args.viewpoint_mm)?);
    let mut file = CameraFile::new(spec);
    let mut report = cal.report_json();
    report["model"] = serde_json::json!(format!("{:?}", args.model).to_lowercase());
    report["board"] = serde_json::json!({"inner_cols": board.inner_cols, "inner_rows": board.inner_rows, "square_mm": board.square_mm});
    if let Some(a) = annulus {
        report["annulus_px"] = serde_json::json!(a);
    }
    report["warnings"] = serde_json::json!(warnings);
    if let Some(h) = held_out {
        report["held_out"] = serde_json::json!({
            "folds": h.folds, "test_rms_per_corner_px": h.test_rms_px,
            "train_rms_per_corner_px": h.train_rms_px, "test_corners": h.test_corners,
        });
    }
    file.report = Some(report);
    write_doc(&args.output, &file)?;
    Ok(())
}

fn print_summary(cal: &Calibration) {
    for img in &cal.images {
        match (img.used, img.rms_px, img.reason.as_ref()) {
            (true, Some(r), _) => {
                eprintln!(
                    "  {}: {} corners, RMS {:.3} px per corner",
                    img.name,
                    img.corners,
                    r * std::f64::consts::SQRT_2
                )
            }
            (_, _, Some(why)) => eprintln!("  {}: rejected: {why}", img.name),
            _ => eprintln!("  {}: rejected", img.name),
        }
    }
    let used = cal.images.iter().filter(|i| i.used).count();
    eprintln!(
        "RMS reprojection error {:.3} px per corner (Euclidean, as OpenCV and Kalibr print; {:.3} px per coordinate) over {used} of {} images",
        cal.rms_per_corner_px(),
        cal.rms_px,
        cal.images.len()
    );
    for ((n, v), s) in cal.param_names.iter().zip(&cal.params).zip(&cal.std_devs) {
        eprintln!("  {n} = {v:.6e} ± {s:.2e}");
    }
}

fn write_overlays(dir: &Path, cal: &Calibration, obs: &[Observation], detected: &Detected) -> CliResult {
    if detected.images.is_empty() {
        return Err(CliError::usage("--overlay needs images (it cannot be used with --corners)"));
    }
    std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    for (k, (o, img)) in obs.iter().zip(&detected.images).enumerate() {
        let Some(img) = img else { continue };
        let reproj: Vec<[f64; 2]> = cal.reprojected(k, o).into_iter().flatten().collect();
        let picture = overlay::draw_overlay(img, &o.pixels, &reproj);
        let stem = Path::new(&o.name).file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or(format!("{k}"));
        let path = dir.join(format!("{stem}.png"));
        omni_vision::image_io::write_rgb_png(&path, picture.width(), picture.height(), picture.as_raw())?;
    }
    Ok(())
}

fn write_text(path: &Path, text: &str) -> CliResult {
    omni_formats::io::write_atomic(path, |w| w.write_all(text.as_bytes()))?;
    Ok(())
}

fn write_exports(args: &CalibArgs, cal: &Calibration) -> CliResult {
    match &cal.spec {
        CameraSpec::Ocam(p) => {
            if let Some(path) = &args.export_ocam {
                let (text, fit) = export::ocam_calib_results(p);
                report_inverse_fit(&fit);
                write_text(path, &text)?;
            }
        }
        CameraSpec::Mei(p) => {
            if let Some(path) = &args.export_kalibr {
                write_text(path, &export::kalibr_camchain(p, &args.rostopic))?;
            }
            if let Some(path) = &args.export_opencv {
                write_text(path, &export::opencv_omnidir_yaml(p))?;
            }
        }
        _ => {}
    }
    Ok(())
}
