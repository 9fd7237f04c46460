//! camera.json to and from other tools' files (OCamCalib, Kalibr, OpenCV), into another model
//! ([`convert`]), and the question-and-answer loop ([`query`]).

use super::{Error, Reporter, inverse_fit_line, read_mirror, stage_text};
use crate::receiver::{ModelKind, convert as conversion, export, query as questions};
use omni_formats::{CameraFile, CameraSpec, read_doc, write_doc};
use omni_model::HyperbolicParams;
use std::io::BufRead as _;
use std::path::{Path, PathBuf};

/// The text of an input file (`-` = stdin) and its name for messages.
fn read_text(input: &Path) -> Result<(String, String), Error> {
    let name = omni_formats::io::display_name(input, "stdin");
    let bytes = omni_formats::io::read_all(input)?;
    let text = String::from_utf8(bytes).map_err(|_| format!("{name}: not UTF-8 text"))?;
    Ok((text, name))
}

/// OCamCalib's calib_results.txt (`-` = stdin) to camera.json (kind ocam) at `output`.
pub fn import_ocam(input: &Path, output: &Path) -> Result<(), Error> {
    let (text, name) = read_text(input)?;
    let (params, origin) = export::parse_ocam_calib_results(&text).map_err(|e| format!("{name}: {e}"))?;
    let mut file = CameraFile::new(CameraSpec::Ocam(params));
    file.report = Some(serde_json::json!({"imported_from": name, "centre": origin.describe()}));
    write_doc(output, &file)?;
    Ok(())
}

/// Camera `cam` of a Kalibr camchain.yaml (`-` = stdin) to camera.json (kind mei, pinhole or
/// fisheye, as the file's camera and distortion models say).
pub fn import_kalibr(input: &Path, cam: &str, viewpoint: Option<&str>, output: &Path) -> Result<(), Error> {
    let viewpoint_prefix = format!("{cam}.");
    import_spec(input, output, "kalibr", |t| export::parse_kalibr_camera(t, cam), (viewpoint, &viewpoint_prefix))
}

/// An OpenCV FileStorage YAML file (`-` = stdin) of the model `which` (omnidir, calibrateCamera's
/// pinhole, fisheye; auto: see [`export::OpencvModel::Auto`]) to camera.json.
pub fn import_opencv(
    input: &Path,
    which: export::OpencvModel,
    viewpoint: Option<&str>,
    output: &Path,
) -> Result<(), Error> {
    import_spec(input, output, "opencv", |t| export::parse_opencv(t, which), (viewpoint, ""))
}

/// Imports a Kalibr or OpenCV file with `parse`; `source` names the source format. The
/// viewpoint (mm) is `--viewpoint-mm` (`viewpoint.0`) if given, else the one an omniscan export
/// kept in the file under `viewpoint.1` ([`export::VIEWPOINT_KEY`]), else the origin.
fn import_spec(
    input: &Path,
    output: &Path,
    source: &str,
    parse: impl Fn(&str) -> Result<CameraSpec, String>,
    (viewpoint, viewpoint_prefix): (Option<&str>, &str),
) -> Result<(), Error> {
    let (text, name) = read_text(input)?;
    let mut spec = parse(&text).map_err(|e| format!("{name}: {e}"))?;
    let kept = export::viewpoint_in(&text, viewpoint_prefix).map_err(|e| format!("{name}: {e}"))?;
    match viewpoint {
        Some(v) => spec.set_viewpoint_mm(super::parse_viewpoint(v)?),
        None => spec.set_viewpoint_mm(kept.unwrap_or([0.0; 3])),
    }
    let (format, frame) = match &spec {
        CameraSpec::Mei(_) => (format!("{source}-omni"), export::FRAME_NOTE),
        other => (format!("{source}-{}", other.kind()), export::CAMERA_FRAME_NOTE),
    };
    let mut file = CameraFile::new(spec);
    file.report = Some(serde_json::json!({"imported_from": name, "source_format": format, "frame": frame}));
    write_doc(output, &file)?;
    Ok(())
}

/// `omni-calib-receiver export`: a camera.json in another tool's format.
#[derive(Debug, Clone)]
pub struct ExportOptions {
    /// The calibration (camera.json).
    pub camera: PathBuf,
    /// `ocam` (from kind ocam), `kalibr` or `opencv` (from kind mei).
    pub to: String,
    /// The Kalibr image topic.
    pub rostopic: String,
    /// Output file (`-` = stdout).
    pub output: PathBuf,
}

/// Writes the camera in the format `opts.to`; a camera of the wrong kind is an error naming it.
pub fn export_camera(opts: &ExportOptions, out: &dyn Reporter) -> Result<(), Error> {
    let file: CameraFile = read_doc(&opts.camera)?;
    let refused = |e: String| Error::Failed(format!("{}: --to {} {e}", opts.camera.display(), opts.to));
    let text = match (opts.to.as_str(), &file.model) {
        ("ocam", CameraSpec::Ocam(p)) => {
            let (text, fit) = export::ocam_calib_results(p);
            out.say(&inverse_fit_line(&fit));
            text
        }
        ("ocam", model) => {
            return Err(Error::Failed(format!(
                "{}: --to ocam needs a camera of kind ocam, this one is {}",
                opts.camera.display(),
                model.kind()
            )));
        }
        ("kalibr", model) => export::kalibr_camchain_of(model, &opts.rostopic).map_err(refused)?,
        (_, model) => export::opencv_yaml_of(model).map_err(refused)?,
    };
    Ok(stage_text(&opts.output, &text)?.commit()?)
}

/// `omni-calib-receiver convert`: a calibration into another model, fitted to its rays.
#[derive(Debug, Clone)]
pub struct ConvertOptions {
    /// The calibration (camera.json).
    pub camera: PathBuf,
    pub to: ModelKind,
    /// For [`ModelKind::Hyperbolic`]: camera.json of kind hyperbolic giving the mirror; default
    /// the source's mirror if it is hyperbolic, else [`HyperbolicParams::paper`].
    pub mirror: Option<PathBuf>,
    /// Largest ray difference accepted (deg).
    pub max_ray_deg: f64,
    /// Largest pixel difference accepted (px).
    pub max_pixel_px: f64,
    /// Output camera.json (`-` = stdout).
    pub output: PathBuf,
}

/// Converts, reports the largest differences and writes the result only within the limits.
pub fn convert(opts: &ConvertOptions, out: &dyn Reporter) -> Result<(), Error> {
    let camera = &opts.camera;
    let to = opts.to;
    let source: CameraFile = read_doc(camera)?;
    let mirror = match (&opts.mirror, &source.model) {
        (Some(p), _) => read_mirror(p)?,
        (None, CameraSpec::Hyperbolic(h)) => h.clone(),
        (None, _) => HyperbolicParams::paper(),
    };
    let c = conversion::convert(&source.model, to, &mirror).map_err(|e| format!("{}: {e}", camera.display()))?;
    out.say(&format!(
        "converted to {to:?} over {} pixels of the annulus: rays within {:.4}°, pixels within {:.4} px",
        c.samples, c.max_ray_deg, c.max_pixel_px
    ));
    if !(c.max_ray_deg <= opts.max_ray_deg && c.max_pixel_px <= opts.max_pixel_px) {
        return Err(Error::Failed(format!(
            "{}: the {to:?} model differs from the source by up to {:.4}° / {:.4} px (limits --max-ray-deg {} / --max-pixel-px {}); not written",
            camera.display(),
            c.max_ray_deg,
            c.max_pixel_px,
            opts.max_ray_deg,
            opts.max_pixel_px
        )));
    }
    // The lens, its blur and the colour filters are the same camera's whatever the model.
    let mut file = CameraFile {
        optics: source.optics,
        lens_blur_px: source.lens_blur_px,
        colour: source.colour.clone(),
        ..CameraFile::new(c.spec)
    };
    file.report = Some(serde_json::json!({
        "converted_from": camera.display().to_string(),
        "max_ray_difference_deg": c.max_ray_deg,
        "max_pixel_difference_px": c.max_pixel_px,
        "pixels_compared": c.samples,
    }));
    write_doc(&opts.output, &file)?;
    Ok(())
}

/// `omni-calib-receiver query`: questions to a calibration, one per line.
#[derive(Debug, Clone)]
pub struct QueryOptions {
    /// The calibration (camera.json).
    pub camera: PathBuf,
    /// Questions (`-` = stdin).
    pub input: PathBuf,
    /// Answers (`-` = stdout).
    pub output: PathBuf,
    /// Answer in JSON, one object per line.
    pub json: bool,
}

/// Answers the questions line by line (stdout is flushed after each answer, so a pipe gets it as
/// it asks). A bad question stops with an error naming its line; a file output is then not
/// written, stdout keeps the answers so far.
pub fn query(opts: &QueryOptions) -> Result<(), Error> {
    let (_, cam) = CameraFile::load(&opts.camera)?;
    let name = omni_formats::io::display_name(&opts.input, "stdin");
    let reader = omni_formats::io::open_input(&opts.input)?;
    let to_stdout = opts.output == Path::new("-");
    let mut failure: Option<String> = None;
    omni_formats::io::write_atomic(&opts.output, |w| {
        for (n, line) in reader.lines().enumerate() {
            let line = match line {
                Ok(line) => line,
                Err(e) => {
                    failure = Some(format!("{name}: line {}: {e}", n + 1));
                    return Err(std::io::Error::other("unreadable input"));
                }
            };
            match questions::parse_query(&line) {
                Ok(None) => {}
                Ok(Some(q)) => {
                    writeln!(w, "{}", questions::answer(cam.as_ref(), q, opts.json))?;
                    if to_stdout {
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
    .map_err(|e| Error::Failed(failure.take().unwrap_or_else(|| e.to_string())))
}
