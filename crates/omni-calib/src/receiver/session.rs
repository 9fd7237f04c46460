//! What each command of `omni-calib-receiver` does between reading its options and exiting: the
//! calibration from board images or a corners file ([`calibrate`]), the mirror annulus
//! ([`find_annulus`]), and the camera.json conversions and the query loop ([`files`]).
//!
//! Each command is one function of a plain options struct. Lines for the person running it (the
//! annulus found, the per-image summary, warnings, detection progress) go to a [`Reporter`];
//! a failure comes back as an [`Error`] that says whether the options or the input were at fault.
//! Messages name the tool's flags (`--annulus`, `--overlay`, …), as the tool prints them as they are.

mod annulus;
pub mod files;

pub use annulus::{find_annulus, parse_annulus};
pub use files::{ConvertOptions, ExportOptions, QueryOptions, convert, export_camera, import_kalibr, import_ocam};
pub use files::{import_opencv, query};

use super::corners_file::{CornersFile, ImageCorners};
use super::validate::{self, HeldOut};
use super::{Calibration, ModelKind, Observation, Options, export};
use omni_formats::io::Staged;
use omni_formats::{BoardFile, CameraFile, CameraSpec, read_doc, stage_doc};
use omni_model::HyperbolicParams;
use omni_vision::corners::{DetectorOptions, GrayF32, detect_board, edge_blur, load_gray, overlay};
use omni_vision::image_io::expand_image_paths;
use rayon::prelude::*;
use std::path::{Path, PathBuf};

/// Why a command failed. No `Display` on purpose: the tool must map the kind to its exit code
/// ([`Error::Usage`] → 2, [`Error::Failed`] → 1) and not let a generic conversion hide it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Error {
    /// Options that do not go together or do not parse.
    Usage(String),
    /// Bad input, an I/O failure or a failed calibration; the message names the file at fault.
    Failed(String),
}

impl Error {
    /// The one-line message.
    pub fn message(&self) -> &str {
        match self {
            Error::Usage(m) | Error::Failed(m) => m,
        }
    }
}

impl From<String> for Error {
    fn from(message: String) -> Self {
        Error::Failed(message)
    }
}

impl From<omni_formats::Error> for Error {
    fn from(e: omni_formats::Error) -> Self {
        Error::Failed(e.to_string())
    }
}

/// Where a command's messages go; the tool prints them on stderr, tests collect them.
pub trait Reporter: Sync {
    /// One line for the person running the command.
    fn say(&self, line: &str);
    /// A warning about the result.
    fn warn(&self, message: &str);
    /// Corner detection starts on `images` images.
    fn detection_started(&self, _images: usize) {}
    /// One more image is done (called from the detection threads).
    fn image_detected(&self) {}
    /// Corner detection is over.
    fn detection_finished(&self) {}
}

/// The options of a calibration (`omni-calib-receiver --board … IMAGES`).
#[derive(Debug, Clone)]
pub struct CalibrateOptions {
    /// The checkerboard (board.json).
    pub board: PathBuf,
    pub model: ModelKind,
    /// A corners file to fit instead of detecting corners in `images`.
    pub corners: Option<PathBuf>,
    /// Where to write the detected corners.
    pub save_corners: Option<PathBuf>,
    /// A directory for one overlay PNG per image (needs `images`).
    pub overlay: Option<PathBuf>,
    /// camera.json to write (`-` = stdout).
    pub output: PathBuf,
    /// camera.json of kind hyperbolic giving the mirror; default [`HyperbolicParams::paper`].
    pub mirror: Option<PathBuf>,
    /// For [`ModelKind::Hyperbolic`]: fit the camera's offset from the mirror's focus and its
    /// tilt too ([`Options::non_central`]).
    pub non_central: bool,
    /// OCamCalib calib_results.txt to export (needs [`ModelKind::Ocam`]).
    pub export_ocam: Option<PathBuf>,
    /// Kalibr camchain.yaml to export (needs [`ModelKind::Mei`]).
    pub export_kalibr: Option<PathBuf>,
    /// OpenCV omnidir YAML to export (needs [`ModelKind::Mei`]).
    pub export_opencv: Option<PathBuf>,
    /// The image topic of the Kalibr export.
    pub rostopic: String,
    /// K of the K-fold held-out validation; 0 = none.
    pub folds: usize,
    /// Also a leave-one-image-out jackknife σ of each parameter ([`validate::jackknife`]).
    pub jackknife: bool,
    /// Huber threshold of the robust loss (px).
    pub huber_px: f64,
    /// Plain least squares: no Huber loss, no per-image weights, no image rejected as an outlier
    /// (the cost OpenCV and Kalibr minimise, to compare RMS values with theirs).
    pub least_squares: bool,
    /// The fitted model's viewpoint in the world frame, `X,Y,Z` (mm) as typed; parsed before
    /// anything is read.
    pub viewpoint_mm: String,
    /// `CX,CY,R_IN,R_OUT` (px) or `auto` (found in the board images); `None` with no
    /// `rim_image`: the whole image.
    pub annulus: Option<String>,
    /// An image of a lit scene to find the annulus in.
    pub rim_image: Option<PathBuf>,
    /// Board images (files or directories; see [`expand_image_paths`]).
    pub images: Vec<PathBuf>,
}

impl CalibrateOptions {
    /// Default settings of the tool for the board `board` and these images.
    pub fn new(board: PathBuf, images: Vec<PathBuf>) -> Self {
        CalibrateOptions {
            board,
            model: ModelKind::Mei,
            corners: None,
            save_corners: None,
            overlay: None,
            output: PathBuf::from("camera.json"),
            mirror: None,
            non_central: false,
            export_ocam: None,
            export_kalibr: None,
            export_opencv: None,
            rostopic: export::DEFAULT_ROSTOPIC.to_string(),
            folds: 0,
            jackknife: false,
            huber_px: 1.0,
            least_squares: false,
            viewpoint_mm: "0,0,0".to_string(),
            annulus: None,
            rim_image: None,
            images,
        }
    }
}

/// The options read before any file is: the viewpoint and the annulus as given.
struct Checked<'a> {
    viewpoint_mm: [f64; 3],
    annulus: Option<annulus::Given<'a>>,
}

/// Checks what a parser cannot, before anything is read or written: exports that need another
/// model, overlays without images, the Huber threshold; parses the viewpoint and the annulus.
fn check_options(opts: &CalibrateOptions) -> Result<Checked<'_>, Error> {
    if opts.export_ocam.is_some() && opts.model != ModelKind::Ocam {
        return Err(Error::Usage("--export-ocam needs --model ocam".into()));
    }
    let kalibr_or_opencv = matches!(opts.model, ModelKind::Mei | ModelKind::PinholeRadtan | ModelKind::Fisheye);
    if opts.export_kalibr.is_some() && !kalibr_or_opencv {
        return Err(Error::Usage(
            "--export-kalibr needs --model mei, pinhole-radtan or fisheye (Kalibr's radtan has no k3)".into(),
        ));
    }
    if opts.export_opencv.is_some() && !(kalibr_or_opencv || opts.model == ModelKind::Pinhole) {
        return Err(Error::Usage("--export-opencv needs --model mei, pinhole, pinhole-radtan or fisheye".into()));
    }
    if opts.overlay.is_some() && opts.corners.is_some() {
        return Err(Error::Usage("--overlay needs images (it cannot be used with --corners)".into()));
    }
    if !(opts.huber_px.is_finite() && opts.huber_px > 0.0) {
        return Err(Error::Usage("--huber-px must be a positive number".into()));
    }
    let outputs = [&opts.save_corners, &opts.export_ocam, &opts.export_kalibr, &opts.export_opencv];
    for path in std::iter::once(&opts.output).chain(outputs.into_iter().flatten()) {
        omni_formats::io::check_output_dir(path)?;
    }
    Ok(Checked {
        viewpoint_mm: parse_viewpoint(&opts.viewpoint_mm)?,
        annulus: annulus::given(opts.annulus.as_deref(), opts.rim_image.as_deref(), opts.corners.is_none())?,
    })
}

/// `X,Y,Z` (mm), all finite.
pub fn parse_viewpoint(s: &str) -> Result<[f64; 3], Error> {
    let v: Vec<f64> = s.split(',').filter_map(|t| t.trim().parse().ok()).collect();
    match v[..] {
        [x, y, z] if v.iter().all(|c: &f64| c.is_finite()) && s.split(',').count() == 3 => Ok([x, y, z]),
        _ => Err(Error::Usage(format!("--viewpoint-mm: expected X,Y,Z in mm, got {s:?}"))),
    }
}

/// Places the generic model's viewpoint (the exact hyperbolic model has its own, at 2c).
fn set_viewpoint(spec: &mut CameraSpec, viewpoint: [f64; 3]) {
    spec.set_viewpoint_mm(viewpoint);
}

/// The mirror of a camera.json of kind hyperbolic (`--mirror`).
fn read_mirror(path: &Path) -> Result<HyperbolicParams, Error> {
    match read_doc::<CameraFile>(path)?.model {
        CameraSpec::Hyperbolic(h) => Ok(h),
        _ => Err(Error::Failed(format!("{}: --mirror needs a camera of kind hyperbolic", path.display()))),
    }
}

/// Detected corners, the images (kept for the overlays) and the lens's blur on each image's
/// board edges (px, where measured).
struct Detected {
    corners: CornersFile,
    images: Vec<Option<GrayF32>>,
    blurs: Vec<f64>,
}

/// The lens's blur over the images (PSF σ, px): median, fewest and most, and how many images.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LensBlur {
    pub median_px: f64,
    pub min_px: f64,
    pub max_px: f64,
    pub images: usize,
}

impl LensBlur {
    /// Over the images' blurs; `None` if there are none.
    pub fn of(blurs: &[f64]) -> Option<LensBlur> {
        if blurs.is_empty() {
            return None;
        }
        let mut blurs = blurs.to_vec();
        blurs.sort_by(f64::total_cmp);
        let n = blurs.len();
        let median_px = if n % 2 == 1 { blurs[n / 2] } else { 0.5 * (blurs[n / 2 - 1] + blurs[n / 2]) };
        Some(LensBlur { median_px, min_px: blurs[0], max_px: blurs[n - 1], images: n })
    }

    /// The line the tool prints.
    pub fn line(&self) -> String {
        format!(
            "lens blur on the board edges: PSF σ {:.2} px (median of {} images, {:.2}-{:.2}), in camera.json as \
             lens_blur_px: omni-ridge --camera removes only the lens's pull from curved stripes",
            self.median_px, self.images, self.min_px, self.max_px
        )
    }

    /// Its entry in the report.
    pub fn json(&self) -> serde_json::Value {
        serde_json::json!({
            "psf_sigma_px": self.median_px, "min_px": self.min_px, "max_px": self.max_px, "images": self.images,
        })
    }
}

/// Detects the board in every image (in parallel); all images must have one size.
fn detect(
    paths: &[PathBuf],
    board: &BoardFile,
    annulus: Option<[f64; 4]>,
    keep_images: bool,
    out: &dyn Reporter,
) -> Result<Detected, Error> {
    let detector = DetectorOptions { annulus, ..Default::default() };
    out.detection_started(paths.len());
    // Each image, its corners and its edges' blur (px).
    type OneImage = (GrayF32, ImageCorners, Option<f64>);
    let results: Vec<Result<OneImage, String>> = paths
        .par_iter()
        .map(|p| {
            let img = load_gray(p)?;
            let name = p.display().to_string();
            let found = detect_board(&img, board.inner_cols, board.inner_rows, &detector);
            let blur = found.as_ref().ok().and_then(|b| edge_blur(&img, b)).map(|e| e.sigma_px);
            out.image_detected();
            let entry = ImageCorners::from_detection(name, found);
            Ok((img, entry, blur))
        })
        .collect();
    out.detection_finished();
    let mut size: Option<(usize, usize, String)> = None;
    let mut file = CornersFile::new(0, 0, board.inner_cols, board.inner_rows);
    let mut images = Vec::new();
    let mut blurs = Vec::new();
    for r in results {
        let (img, entry, blur) = r?;
        blurs.extend(blur);
        match &size {
            None => size = Some((img.width, img.height, entry.name.clone())),
            Some((w, h, first)) if (*w, *h) != (img.width, img.height) => {
                return Err(Error::Failed(format!(
                    "{}: image is {} × {} px but {first} is {w} × {h} px (all images must come from one camera)",
                    entry.name, img.width, img.height
                )));
            }
            _ => {}
        }
        file.images.push(entry);
        images.push(keep_images.then_some(img));
    }
    let (w, h, _) = size.ok_or_else(|| Error::Failed("no images given".into()))?;
    file.width = w as u32;
    file.height = h as u32;
    Ok(Detected { corners: file, images, blurs })
}

/// A corners file, checked and matched against the board.
fn load_corners(path: &Path, board: &BoardFile) -> Result<CornersFile, Error> {
    let file: CornersFile = read_doc(path)?;
    file.validate().map_err(|e| format!("{}: {e}", path.display()))?;
    if (file.inner_cols, file.inner_rows) != (board.inner_cols, board.inner_rows) {
        return Err(Error::Failed(format!(
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

/// Calibrates: checks the options and parses the numbers in them (bad ones are refused before any
/// file is read or written), reads the board, finds the annulus, detects (or reads) the corners,
/// fits, reports the fit, writes the overlays and exports asked for and finally camera.json with
/// its report. camera.json is written only if everything before succeeded.
pub fn calibrate(opts: &CalibrateOptions, out: &dyn Reporter) -> Result<(), Error> {
    let checked = check_options(opts)?;
    let board: BoardFile = read_doc(&opts.board)?;
    board.validate().map_err(|e| format!("{}: {e}", opts.board.display()))?;
    let mirror = match &opts.mirror {
        Some(p) => read_mirror(p)?,
        None => HyperbolicParams::paper(),
    };
    let paths = if opts.corners.is_some() { Vec::new() } else { expand_image_paths(&opts.images)? };
    let annulus = annulus::resolve(checked.annulus.as_ref(), &paths, out)?;
    let detected = match &opts.corners {
        Some(path) => Detected { corners: load_corners(path, &board)?, images: Vec::new(), blurs: Vec::new() },
        None => detect(&paths, &board, annulus.as_ref().map(|a| a.annulus), opts.overlay.is_some(), out)?,
    };
    if let Some(annulus::Resolved { source: Some((rim_w, rim_h, rim_source)), .. }) = &annulus
        && (*rim_w, *rim_h) != (detected.corners.width as usize, detected.corners.height as usize)
    {
        return Err(Error::Failed(format!(
            "{rim_source}: image is {rim_w} × {rim_h} px but the board images are {} × {} px",
            detected.corners.width, detected.corners.height
        )));
    }
    let annulus = annulus.map(|a| a.annulus);
    // Every output is staged and put in place at the end, once all of them succeeded.
    let mut staged = Vec::new();
    if let Some(path) = &opts.save_corners {
        staged.push(stage_doc(path, &detected.corners)?);
    }
    let corners = &detected.corners;
    let obs = corners.observations(board.square_mm);
    let mut fit = Options {
        model: opts.model,
        huber_px: opts.huber_px,
        mirror,
        annulus,
        non_central: opts.non_central,
        ..Default::default()
    };
    if opts.least_squares {
        fit = Options { huber_px: f64::INFINITY, outlier_factor: f64::INFINITY, reweight_images: false, ..fit };
    }
    let mut cal = super::calibrate(corners.width, corners.height, &obs, &fit).map_err(|e| {
        let reasons: Vec<String> =
            corners.images.iter().filter_map(|i| i.reason.as_ref().map(|r| format!("{}: {r}", i.name))).collect();
        match reasons.is_empty() {
            true => Error::Failed(format!("calibration failed: {e}")),
            false => Error::Failed(format!("calibration failed: {e}; {}", reasons.join("; "))),
        }
    })?;
    // The detector's reason ("no board found", …) says more than "too few corners (0 < 8)".
    for (img, entry) in cal.images.iter_mut().zip(&corners.images) {
        if entry.reason.is_some() {
            img.reason = entry.reason.clone();
        }
    }
    for line in summary_lines(&cal) {
        out.say(&line);
    }
    let lens_blur = LensBlur::of(&detected.blurs);
    if let Some(b) = &lens_blur {
        out.say(&b.line());
    }
    let warnings: Vec<String> =
        corners.board_size_warning().into_iter().chain(validate::warnings(&cal, &fit)).collect();
    for w in &warnings {
        out.warn(w);
    }
    let held_out = match opts.folds {
        0 => None,
        k => {
            let h = validate::k_fold(corners.width, corners.height, &obs, &fit, k)?;
            out.say(&format!(
                "held-out RMS per corner ({k}-fold, {} corners): test {:.3} px, training {:.3} px",
                h.test_corners, h.test_rms_px, h.train_rms_px
            ));
            Some(h)
        }
    };
    let jackknife = match opts.jackknife {
        false => None,
        true => {
            let sigmas = validate::jackknife(corners.width, corners.height, &obs, &fit, &cal)?;
            out.say("leave-one-image-out jackknife σ (the fit's own σ in brackets):");
            for ((n, s), own) in cal.param_names.iter().zip(&sigmas).zip(&cal.std_devs) {
                out.say(&format!("  {n} ± {s:.2e} ({own:.2e})"));
            }
            Some(sigmas)
        }
    };
    if let Some(dir) = &opts.overlay {
        write_overlays(dir, &cal, &obs, &detected.images)?;
    }
    // The exports carry the viewpoint too (as `omniscan_viewpoint_mm` or an OCamCalib comment).
    let mut spec = cal.spec.clone();
    set_viewpoint(&mut spec, checked.viewpoint_mm);
    staged.extend(stage_exports(opts, &spec, out)?);
    let mut file = CameraFile::new(spec);
    file.lens_blur_px = lens_blur.map(|b| b.median_px);
    let mut r = report(&cal, opts.model, &board, annulus, &warnings, held_out.as_ref());
    if let Some(b) = &lens_blur {
        r["lens_blur"] = b.json();
    }
    for (n, s) in cal.param_names.iter().zip(jackknife.iter().flatten()) {
        r["parameters"][n]["jackknife_std"] = serde_json::json!(s);
    }
    file.report = Some(r);
    staged.push(stage_doc(&opts.output, &file)?);
    omni_formats::io::commit_all(staged)?;
    Ok(())
}

/// The report stored in camera.json: [`Calibration::report_json`] with the model, the board, the
/// annulus used (if any), the warnings and the held-out validation (if run).
pub fn report(
    cal: &Calibration,
    model: ModelKind,
    board: &BoardFile,
    annulus: Option<[f64; 4]>,
    warnings: &[String],
    held_out: Option<&HeldOut>,
) -> serde_json::Value {
    let mut report = cal.report_json();
    report["model"] = serde_json::json!(model.name());
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
    report
}

/// The summary printed after a fit: one line per image (corners and RMS per corner, or why it was
/// rejected), the overall RMS, one line per fitted parameter with its standard deviation.
pub fn summary_lines(cal: &Calibration) -> Vec<String> {
    let mut lines = Vec::new();
    for img in &cal.images {
        lines.push(match (img.used, img.rms_px, img.reason.as_ref()) {
            (true, Some(r), _) => format!(
                "  {}: {} corners, RMS {:.3} px per corner",
                img.name,
                img.corners,
                r * std::f64::consts::SQRT_2
            ),
            (_, _, Some(why)) => format!("  {}: rejected: {why}", img.name),
            _ => format!("  {}: rejected", img.name),
        });
    }
    let used = cal.images.iter().filter(|i| i.used).count();
    lines.push(format!(
        "RMS reprojection error {:.3} px per corner (Euclidean, as OpenCV and Kalibr print; {:.3} px per coordinate) over {used} of {} images",
        cal.rms_per_corner_px(),
        cal.rms_px,
        cal.images.len()
    ));
    for ((n, v), s) in cal.param_names.iter().zip(&cal.params).zip(&cal.std_devs) {
        lines.push(format!("  {n} = {v:.6e} ± {s:.2e}"));
    }
    lines
}

/// One PNG per image in `dir` (named after the image) with the detected and reprojected corners.
fn write_overlays(dir: &Path, cal: &Calibration, obs: &[Observation], images: &[Option<GrayF32>]) -> Result<(), Error> {
    std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    for (k, (o, img)) in obs.iter().zip(images).enumerate() {
        let Some(img) = img else { continue };
        let reproj: Vec<[f64; 2]> = cal.reprojected(k, o).into_iter().flatten().collect();
        let picture = overlay::draw_overlay(img, &o.pixels, &reproj);
        let stem = Path::new(&o.name).file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or(format!("{k}"));
        let path = dir.join(format!("{stem}.png"));
        omni_vision::image_io::write_rgb_png(&path, picture.width(), picture.height(), picture.as_raw())?;
    }
    Ok(())
}

/// Writes `text` to `path` (`-` = stdout), staged ([`omni_formats::io::write_staged`]).
fn stage_text(path: &Path, text: &str) -> Result<Staged, Error> {
    Ok(omni_formats::io::write_staged(path, |w| w.write_all(text.as_bytes()))?)
}

/// The line reporting how well OCamCalib's inverse polynomial follows the direct one.
fn inverse_fit_line(fit: &omni_model::ocam::InverseFit) -> String {
    format!(
        "OCamCalib inverse polynomial: degree {}, within {:.4} px of the direct one over radii {:.1}–{:.1} px",
        fit.degree, fit.max_error_px, fit.rho_range_px[0], fit.rho_range_px[1]
    )
}

/// The exports asked for that the fitted model allows, staged.
fn stage_exports(opts: &CalibrateOptions, spec: &CameraSpec, out: &dyn Reporter) -> Result<Vec<Staged>, Error> {
    let mut staged = Vec::new();
    match spec {
        CameraSpec::Ocam(p) => {
            if let Some(path) = &opts.export_ocam {
                let (text, fit) = export::ocam_calib_results(p);
                out.say(&inverse_fit_line(&fit));
                staged.push(stage_text(path, &text)?);
            }
        }
        spec => {
            if let Some(path) = &opts.export_kalibr {
                staged.push(stage_text(path, &export::kalibr_camchain_of(spec, &opts.rostopic)?)?);
            }
            if let Some(path) = &opts.export_opencv {
                staged.push(stage_text(path, &export::opencv_yaml_of(spec)?)?);
            }
        }
    }
    Ok(staged)
}

#[cfg(test)]
mod tests;
