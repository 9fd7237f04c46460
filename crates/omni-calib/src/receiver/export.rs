//! Interoperability: OCamCalib `calib_results.txt` (export and import), Kalibr `camchain.yaml`
//! (`omni` + `radtan`, `pinhole` + `radtan`, `pinhole` + `equidistant`) and OpenCV's
//! `omnidir` (K, D, ξ), `calibrateCamera` (camera_matrix, distortion_coefficients) and
//! `fisheye` (K, D) parameters as OpenCV FileStorage YAML files.
//!
//! The ordinary models (kinds pinhole and fisheye) are OpenCV's and Kalibr's own formulas in
//! the camera frame (x, y, −z) of ours: the same numbers, as for the Mei model.
//!
//! Frames: Kalibr's and OpenCV's unit sphere is (x, y, −z) of the omniscan world, about the
//! viewpoint (`viewpoint_mm`): the image centre looks along their +z, which is our −z. The
//! intrinsics are the same numbers, so the export copies ξ, fx, fy, cx, cy, k1, k2, p1, p2
//! unchanged and writes the frame change into the file as a comment ([`FRAME_NOTE`]).
//! OCamCalib works in (row, column) order: the centre is swapped, and its origin is read from
//! the centre's header ([`CentreOrigin`]).

use super::yaml;
use omni_formats::CameraSpec;
use omni_model::ocam::{INVERSE_MAX_DEGREE, INVERSE_TOLERANCE_PX, InverseFit};
use omni_model::{FisheyeParams, MeiParams, OcamParams, PinholeParams};

/// The frame change between Kalibr/OpenCV and omniscan, as written into exported files.
pub const FRAME_NOTE: &str = "frame: this camera's unit sphere (Xs, Ys, Zs) is (x, y, -z) of the omniscan world frame \
about the viewpoint (omniscan_viewpoint_mm, mm, world frame; camera.json's viewpoint_mm); pixels: x right, y down, (0, 0) at the centre of the top-left pixel";

/// The frame change for the ordinary (pinhole, fisheye) cameras, as written into exported files.
pub const CAMERA_FRAME_NOTE: &str = "frame: this camera's frame (X, Y, Z), Z forward, is (x, y, -z) of the omniscan world frame \
about the viewpoint (omniscan_viewpoint_mm, mm, world frame; camera.json's viewpoint_mm); pixels: x right, y down, (0, 0) at the centre of the top-left pixel";

/// The key an exported file keeps the camera's viewpoint under (mm, omniscan world frame), so
/// that importing it gives back the same rays: neither OpenCV's nor Kalibr's files have one,
/// and both readers pass over keys they do not know.
pub const VIEWPOINT_KEY: &str = "omniscan_viewpoint_mm";

/// A number as YAML 1.1 readers (PyYAML, which Kalibr uses; OpenCV) read a float: the shortest
/// text that reads back to the same f64, with a decimal point and a signed exponent (PyYAML
/// reads `2.4e2` as a string).
pub fn yaml_float(x: f64) -> String {
    let text = format!("{x:e}");
    let (mantissa, exponent) = text.split_once('e').expect("{:e} writes an exponent");
    let mantissa = if mantissa.contains('.') { mantissa.to_string() } else { format!("{mantissa}.0") };
    let exponent = if exponent.starts_with('-') { exponent.to_string() } else { format!("+{exponent}") };
    format!("{mantissa}e{exponent}")
}

/// `[a, b, c]` of [`yaml_float`]s.
fn yaml_list(v: &[f64]) -> String {
    v.iter().map(|x| yaml_float(*x)).collect::<Vec<_>>().join(", ")
}

/// The camera's viewpoint kept in an exported file ([`VIEWPOINT_KEY`]) where `text` has one
/// under `prefix` (`cam0.` in Kalibr's files, nothing in OpenCV's).
pub fn viewpoint_in(text: &str, prefix: &str) -> Result<Option<[f64; 3]>, String> {
    let doc = yaml::FlatYaml::parse(text)?;
    let key = format!("{prefix}{VIEWPOINT_KEY}");
    if !doc.has_prefix(&key) {
        return Ok(None);
    }
    let v = doc.numbers(&key, Some(3))?;
    Ok(Some([v[0], v[1], v[2]]))
}

/// The centre header OCamCalib v3 writes: the values are 0-based, as its C code reads them.
const OCAM_V3_CENTRE_HEADER: &str = "#center: \"row\" and \"column\", starting from 0 (C convention)";

/// Where the pixel origin of a `calib_results.txt` centre is, as its header says.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CentreOrigin {
    /// OCamCalib v3 ("starting from 0 (C convention)"): values are used as written.
    Zero,
    /// Earlier versions ("coordinates (x and y coordinates) of the center of the image"): Matlab's
    /// 1-based pixels, one is subtracted.
    One,
}

impl CentreOrigin {
    /// Reads the origin from the comment line above the centre; `None` if it names no centre.
    fn from_header(header: &str) -> Option<CentreOrigin> {
        let h = header.to_ascii_lowercase();
        if !h.contains("center") && !h.contains("centre") {
            return None;
        }
        Some(if h.contains("starting from 0") { CentreOrigin::Zero } else { CentreOrigin::One })
    }

    /// How camera.json reports it.
    pub fn describe(self) -> &'static str {
        match self {
            CentreOrigin::Zero => "0-based as written (OCamCalib v3 header, C convention)",
            CentreOrigin::One => "1-based (pre-v3 header, Matlab convention): 1 subtracted",
        }
    }
}

/// OCamCalib `calib_results.txt` (v3 layout, centre 0-based) for a polynomial model, with the
/// inverse polynomial refitted over the valid radii until within [`INVERSE_TOLERANCE_PX`]; the
/// fit is returned and noted after the last section (OCamCalib's C reader stops there).
pub fn ocam_calib_results(p: &OcamParams) -> (String, InverseFit) {
    let mut p = p.clone();
    let fit = p.fit_inverse_poly(INVERSE_TOLERANCE_PX, INVERSE_MAX_DEGREE);
    // `{:e}` and `{}` give the shortest text that reads back to the same f64: no digits lost.
    let list = |v: &[f64]| v.iter().map(|x| format!("{x:e}")).collect::<Vec<_>>().join(" ");
    let text = format!(
        "#polynomial coefficients for the DIRECT mapping function (ocam_model.ss in MATLAB). These are used by cam2world\n\n\
         {} {} \n\n\
         #polynomial coefficients for the inverse mapping function (ocam_model.invpol in MATLAB). These are used by world2cam\n\n\
         {} {} \n\n\
         {OCAM_V3_CENTRE_HEADER}\n\n\
         {} {}\n\n\
         #affine parameters \"c\", \"d\", \"e\"\n\n\
         {} {} {}\n\n\
         #image size: \"height\" and \"width\"\n\n\
         {} {}\n\n\
         #omniscan: inverse polynomial of degree {} within {:.4} px of the direct one over radii {:.1}-{:.1} px about the centre\n\
         #omniscan: OCamCalib's (x, y, z) is (y, x, z) of the omniscan world frame about the viewpoint (rows first)\n\
         {OCAM_KEPT} viewpoint_mm {} {} {}\n\
         {OCAM_KEPT} annulus_px {} {}\n",
        p.poly.len(),
        list(&p.poly),
        p.inv_poly.len(),
        list(&p.inv_poly),
        p.cy_px,
        p.cx_px,
        p.c,
        p.d,
        p.e,
        p.height,
        p.width,
        fit.degree,
        fit.max_error_px,
        fit.rho_range_px[0],
        fit.rho_range_px[1],
        p.viewpoint_mm[0],
        p.viewpoint_mm[1],
        p.viewpoint_mm[2],
        p.inner_radius_px,
        p.outer_radius_px,
    );
    (text, fit)
}

/// Parses OCamCalib's `calib_results.txt`; the centre's origin comes from its header. The error
/// names the line or section at fault.
pub fn parse_ocam_calib_results(text: &str) -> Result<(OcamParams, CentreOrigin), String> {
    // Data lines with the comment line last seen above each.
    let mut lines: Vec<(&str, &str)> = Vec::new();
    let mut header = "";
    for line in text.lines().map(str::trim).filter(|l| !l.is_empty()) {
        if line.starts_with('#') {
            header = line;
        } else {
            lines.push((line, header));
        }
    }
    if lines.len() < 5 {
        return Err(format!("expected 5 data lines (poly, inverse poly, centre, affine, size), found {}", lines.len()));
    }
    let numbers = |k: usize, what: &str| -> Result<Vec<f64>, String> {
        lines[k]
            .0
            .split_whitespace()
            .map(|t| t.parse::<f64>().map_err(|_| format!("{what}: \"{t}\" is not a number")))
            .collect::<Result<Vec<f64>, String>>()
            .and_then(|v| {
                if v.iter().all(|x| x.is_finite()) { Ok(v) } else { Err(format!("{what}: values must be finite")) }
            })
    };
    let counted = |k: usize, what: &str| -> Result<Vec<f64>, String> {
        let v = numbers(k, what)?;
        let count = *v.first().ok_or(format!("{what}: empty line"))?;
        if !(count >= 0.0 && count.fract() == 0.0) {
            return Err(format!("{what}: the count of coefficients is {count}, not a whole number ≥ 0"));
        }
        let n = count as usize;
        if v.len() != n + 1 {
            return Err(format!("{what}: says {n} coefficients but has {}", v.len() - 1));
        }
        Ok(v[1..].to_vec())
    };
    let poly = counted(0, "direct polynomial")?;
    let inv_poly = counted(1, "inverse polynomial")?;
    let centre = numbers(2, "centre")?;
    let affine = numbers(3, "affine parameters")?;
    let size = numbers(4, "image size")?;
    if centre.len() != 2 || affine.len() != 3 || size.len() != 2 {
        return Err("centre needs 2 numbers, affine parameters 3, image size 2".into());
    }
    let origin = CentreOrigin::from_header(lines[2].1).ok_or_else(|| {
        format!(
            "centre: the comment above it ({:?}) does not name the centre, so its pixel origin is unknown \
             (OCamCalib v3 writes {OCAM_V3_CENTRE_HEADER:?})",
            lines[2].1
        )
    })?;
    let shift = match origin {
        CentreOrigin::Zero => 0.0,
        CentreOrigin::One => 1.0,
    };
    if size.iter().any(|s| s.fract() != 0.0 || *s < 1.0) {
        return Err(format!("image size: expected whole positive numbers, got {} {}", size[0], size[1]));
    }
    let p = OcamParams {
        poly,
        inv_poly,
        cx_px: centre[1] - shift,
        cy_px: centre[0] - shift,
        c: affine[0],
        d: affine[1],
        e: affine[2],
        width: size[1] as u32,
        height: size[0] as u32,
        inner_radius_px: 0.0,
        outer_radius_px: 0.0,
        viewpoint_mm: [0.0; 3],
    };
    let mut p = p;
    if let Some(v) = ocam_kept(text, "viewpoint_mm", 3)? {
        p.viewpoint_mm = [v[0], v[1], v[2]];
    }
    if let Some(r) = ocam_kept(text, "annulus_px", 2)? {
        (p.inner_radius_px, p.outer_radius_px) = (r[0], r[1]);
    }
    p.validate()?;
    Ok((p, origin))
}

/// The comment that keeps what OCamCalib's file has no place for (the viewpoint, the annulus),
/// so that an exported camera imports back the same.
const OCAM_KEPT: &str = "#omniscan kept:";

/// The `n` numbers of the [`OCAM_KEPT`] line named `name`, if the file has one.
fn ocam_kept(text: &str, name: &str, n: usize) -> Result<Option<Vec<f64>>, String> {
    let prefix = format!("{OCAM_KEPT} {name} ");
    let Some(line) = text.lines().find_map(|l| l.trim().strip_prefix(prefix.as_str())) else {
        return Ok(None);
    };
    let v: Vec<f64> = line.split_whitespace().filter_map(|t| t.parse().ok()).filter(|x: &f64| x.is_finite()).collect();
    match v.len() == n {
        true => Ok(Some(v)),
        false => Err(format!("{OCAM_KEPT} {name}: expected {n} finite numbers, got {line:?}")),
    }
}

/// Kalibr's default image topic for `rostopic` (what `--rostopic` overrides).
pub const DEFAULT_ROSTOPIC: &str = "/omni/image_raw";

/// Kalibr `camchain.yaml` with one camera (`omni` projection, `radtan` distortion), the image
/// topic Kalibr's tools read and no overlapping cameras.
pub fn kalibr_camchain(p: &MeiParams, rostopic: &str) -> String {
    let intrinsics = [p.xi, p.fx_px, p.fy_px, p.cx_px, p.cy_px];
    let d = [p.k1, p.k2, p.p1, p.p2];
    kalibr_text("omni", &intrinsics, "radtan", &d, (p.width, p.height), p.viewpoint_mm, rostopic, FRAME_NOTE)
}

/// Kalibr `camchain.yaml` of any model Kalibr has: Mei (`omni` with `radtan`), pinhole
/// (`pinhole` with `radtan`; Kalibr has no k3, so a pinhole with k3 ≠ 0 is refused) and fisheye
/// (`pinhole` with `equidistant`).
pub fn kalibr_camchain_of(spec: &CameraSpec, rostopic: &str) -> Result<String, String> {
    match spec {
        CameraSpec::Mei(p) => Ok(kalibr_camchain(p, rostopic)),
        CameraSpec::Pinhole(p) => {
            if p.k3 != 0.0 {
                return Err(format!(
                    "needs k3 = 0 (Kalibr's radtan has no k3, this camera has {:e}; fit --model pinhole-radtan for Kalibr)",
                    p.k3
                ));
            }
            let intrinsics = [p.fx_px, p.fy_px, p.cx_px, p.cy_px];
            let d = [p.k1, p.k2, p.p1, p.p2];
            let size = (p.width, p.height);
            Ok(kalibr_text("pinhole", &intrinsics, "radtan", &d, size, p.viewpoint_mm, rostopic, CAMERA_FRAME_NOTE))
        }
        CameraSpec::Fisheye(p) => {
            let intrinsics = [p.fx_px, p.fy_px, p.cx_px, p.cy_px];
            let d = [p.k1, p.k2, p.k3, p.k4];
            let size = (p.width, p.height);
            Ok(kalibr_text(
                "pinhole",
                &intrinsics,
                "equidistant",
                &d,
                size,
                p.viewpoint_mm,
                rostopic,
                CAMERA_FRAME_NOTE,
            ))
        }
        other => Err(format!("needs a camera of kind mei, pinhole or fisheye, this one is {}", other.kind())),
    }
}

#[allow(clippy::too_many_arguments)]
fn kalibr_text(
    model: &str,
    intrinsics: &[f64],
    distortion: &str,
    coeffs: &[f64],
    size: (u32, u32),
    viewpoint_mm: [f64; 3],
    rostopic: &str,
    note: &str,
) -> String {
    format!(
        "# Kalibr camchain ({model} + {distortion}), written by omniscan.\n# {note}.\n\
         cam0:\n  camera_model: {model}\n  intrinsics: [{}]\n  distortion_model: {distortion}\n  \
         distortion_coeffs: [{}]\n  resolution: [{}, {}]\n  cam_overlaps: []\n  rostopic: {rostopic}\n  \
         {VIEWPOINT_KEY}: [{}]\n",
        yaml_list(intrinsics),
        yaml_list(coeffs),
        size.0,
        size.1,
        yaml_list(&viewpoint_mm)
    )
}

/// An OpenCV FileStorage matrix entry (`dt: d`, numbers to full precision).
fn opencv_matrix(name: &str, rows: usize, cols: usize, v: &[f64]) -> String {
    format!("{name}: !!opencv-matrix\n   rows: {rows}\n   cols: {cols}\n   dt: d\n   data: [ {} ]\n", yaml_list(v))
}

/// The viewpoint line of an OpenCV FileStorage file ([`VIEWPOINT_KEY`]).
fn opencv_viewpoint(viewpoint_mm: [f64; 3]) -> String {
    format!("{VIEWPOINT_KEY}: [ {} ]\n", yaml_list(&viewpoint_mm))
}

/// OpenCV's `calibrateCamera` parameters as a FileStorage YAML file, with the keys OpenCV's
/// calibration sample writes: `camera_matrix`, `distortion_coefficients` (k1 k2 p1 p2 k3),
/// `image_width`, `image_height`.
pub fn opencv_pinhole_yaml(p: &PinholeParams) -> String {
    let k = [p.fx_px, 0.0, p.cx_px, 0.0, p.fy_px, p.cy_px, 0.0, 0.0, 1.0];
    format!(
        "%YAML:1.0\n---\n# OpenCV calibrateCamera (camera_matrix, distortion_coefficients = k1 k2 p1 p2 k3), written by omniscan.\n\
         # {CAMERA_FRAME_NOTE}.\nimage_width: {}\nimage_height: {}\n{}{}{}",
        p.width,
        p.height,
        opencv_matrix("camera_matrix", 3, 3, &k),
        opencv_matrix("distortion_coefficients", 5, 1, &[p.k1, p.k2, p.p1, p.p2, p.k3]),
        opencv_viewpoint(p.viewpoint_mm)
    )
}

/// OpenCV's `cv::fisheye` parameters as a FileStorage YAML file: `K`, `D` (k1..k4),
/// `image_width`, `image_height`.
pub fn opencv_fisheye_yaml(p: &FisheyeParams) -> String {
    let k = [p.fx_px, 0.0, p.cx_px, 0.0, p.fy_px, p.cy_px, 0.0, 0.0, 1.0];
    format!(
        "%YAML:1.0\n---\n# OpenCV cv::fisheye (K, D = k1 k2 k3 k4), written by omniscan.\n# {CAMERA_FRAME_NOTE}.\n\
         image_width: {}\nimage_height: {}\n{}{}{}",
        p.width,
        p.height,
        opencv_matrix("K", 3, 3, &k),
        opencv_matrix("D", 4, 1, &[p.k1, p.k2, p.k3, p.k4]),
        opencv_viewpoint(p.viewpoint_mm)
    )
}

/// The OpenCV file of a camera: omnidir (kind mei), calibrateCamera (pinhole) or fisheye.
pub fn opencv_yaml_of(spec: &CameraSpec) -> Result<String, String> {
    match spec {
        CameraSpec::Mei(p) => Ok(opencv_omnidir_yaml(p)),
        CameraSpec::Pinhole(p) => Ok(opencv_pinhole_yaml(p)),
        CameraSpec::Fisheye(p) => Ok(opencv_fisheye_yaml(p)),
        other => Err(format!("needs a camera of kind mei, pinhole or fisheye, this one is {}", other.kind())),
    }
}

/// OpenCV `cv::omnidir` parameters as an OpenCV FileStorage YAML file: `K`, `D`, `xi`.
pub fn opencv_omnidir_yaml(p: &MeiParams) -> String {
    let k = [p.fx_px, 0.0, p.cx_px, 0.0, p.fy_px, p.cy_px, 0.0, 0.0, 1.0];
    format!(
        "%YAML:1.0\n---\n# OpenCV cv::omnidir (K, D = k1 k2 p1 p2, xi), written by omniscan.\n# {FRAME_NOTE}.\n\
         image_width: {}\nimage_height: {}\n{}{}{}{}",
        p.width,
        p.height,
        opencv_matrix("K", 3, 3, &k),
        opencv_matrix("D", 1, 4, &[p.k1, p.k2, p.p1, p.p2]),
        opencv_matrix("xi", 1, 1, &[p.xi]),
        opencv_viewpoint(p.viewpoint_mm)
    )
}

/// A Mei camera of the given intrinsics (ξ, fx, fy, cx, cy, k1, k2, p1, p2) and size, checked.
fn mei_from(v: [f64; 9], width: f64, height: f64) -> Result<MeiParams, String> {
    if !(width.fract() == 0.0 && height.fract() == 0.0 && width >= 1.0 && height >= 1.0) {
        return Err(format!("image size: expected whole positive numbers, got {width} × {height}"));
    }
    let p = MeiParams::from_vector(&v, width as u32, height as u32);
    p.validate()?;
    omni_model::limits::check_image_size(p.width, p.height)?;
    Ok(p)
}

/// Reads camera `cam` of a Kalibr `camchain.yaml` into camera.json's model: `omni` + `radtan`
/// (or `none`) is kind mei, `pinhole` + `radtan` (or `none`) kind pinhole (k3 = 0), `pinhole` +
/// `equidistant` kind fisheye. The error names the key at fault.
pub fn parse_kalibr_camera(text: &str, cam: &str) -> Result<CameraSpec, String> {
    let doc = yaml::FlatYaml::parse(text)?;
    if !doc.has_prefix(cam) {
        let cams = doc.top_keys().join(", ");
        return Err(format!("no camera {cam:?} in the file (it has: {cams})"));
    }
    let key = |k: &str| format!("{cam}.{k}");
    let model = doc.scalar(&key("camera_model"))?;
    let distortion = doc.scalar(&key("distortion_model"))?;
    let coeffs = || doc.numbers(&key("distortion_coeffs"), Some(4));
    let size = doc.numbers(&key("resolution"), Some(2))?;
    let (w, h) = (size[0], size[1]);
    let spec = match (model.as_str(), distortion.as_str()) {
        ("omni", "radtan" | "none") => {
            let i = doc.numbers(&key("intrinsics"), Some(5))?;
            let d = if distortion == "none" { vec![0.0; 4] } else { coeffs()? };
            CameraSpec::Mei(
                mei_from([i[0], i[1], i[2], i[3], i[4], d[0], d[1], d[2], d[3]], w, h)
                    .map_err(|e| format!("{cam}: {e}"))?,
            )
        }
        ("pinhole", "radtan" | "none") => {
            let i = doc.numbers(&key("intrinsics"), Some(4))?;
            let d = if distortion == "none" { vec![0.0; 4] } else { coeffs()? };
            CameraSpec::Pinhole(
                pinhole_from(&[i[0], i[1], i[2], i[3], d[0], d[1], d[2], d[3], 0.0], w, h)
                    .map_err(|e| format!("{cam}: {e}"))?,
            )
        }
        ("pinhole", "equidistant") => {
            let i = doc.numbers(&key("intrinsics"), Some(4))?;
            let d = coeffs()?;
            CameraSpec::Fisheye(
                fisheye_from(&[i[0], i[1], i[2], i[3], d[0], d[1], d[2], d[3]], w, h)
                    .map_err(|e| format!("{cam}: {e}"))?,
            )
        }
        ("omni" | "pinhole", other) => {
            let known = if model == "omni" { "radtan or none" } else { "radtan, equidistant or none" };
            return Err(format!("{}: {other:?} is not read with {model} ({known})", key("distortion_model")));
        }
        (other, _) => {
            return Err(format!("{}: {other:?} is not read (omni or pinhole)", key("camera_model")));
        }
    };
    Ok(spec)
}

fn check_size(width: f64, height: f64) -> Result<(u32, u32), String> {
    if !(width.fract() == 0.0 && height.fract() == 0.0 && width >= 1.0 && height >= 1.0) {
        return Err(format!("image size: expected whole positive numbers, got {width} × {height}"));
    }
    Ok((width as u32, height as u32))
}

/// A pinhole camera of intrinsics fx, fy, cx, cy, k1, k2, p1, p2, k3 and size, checked.
fn pinhole_from(v: &[f64], width: f64, height: f64) -> Result<PinholeParams, String> {
    let (w, h) = check_size(width, height)?;
    let p = PinholeParams::from_vector(v, w, h);
    p.validate()?;
    Ok(p)
}

/// A fisheye camera of intrinsics fx, fy, cx, cy, k1..k4 and size, checked.
fn fisheye_from(v: &[f64], width: f64, height: f64) -> Result<FisheyeParams, String> {
    let (w, h) = check_size(width, height)?;
    let p = FisheyeParams::from_vector(v, w, h);
    p.validate()?;
    Ok(p)
}

/// Which OpenCV model a FileStorage file holds (`import-opencv --model`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum OpencvModel {
    /// `xi` present: omnidir; `camera_matrix` (calibrateCamera's sample names): pinhole; else
    /// refused as ambiguous (K and D of 4 could be either pinhole or fisheye).
    Auto,
    Omnidir,
    Pinhole,
    Fisheye,
}

impl std::str::FromStr for OpencvModel {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "auto" => Ok(OpencvModel::Auto),
            "omnidir" => Ok(OpencvModel::Omnidir),
            "pinhole" => Ok(OpencvModel::Pinhole),
            "fisheye" => Ok(OpencvModel::Fisheye),
            _ => Err(format!("unknown OpenCV model \"{s}\" (known: auto, omnidir, pinhole, fisheye)")),
        }
    }
}

/// Reads an OpenCV FileStorage file of the model `which` into camera.json's model.
pub fn parse_opencv(text: &str, which: OpencvModel) -> Result<CameraSpec, String> {
    let doc = yaml::FlatYaml::parse(text)?;
    let which = match which {
        OpencvModel::Auto if doc.has_prefix("xi") => OpencvModel::Omnidir,
        OpencvModel::Auto if doc.has_prefix("camera_matrix") => OpencvModel::Pinhole,
        OpencvModel::Auto => {
            return Err(
                "no xi and no camera_matrix: say which model K and D are for (--model pinhole or fisheye)".into()
            );
        }
        other => other,
    };
    match which {
        OpencvModel::Omnidir => Ok(CameraSpec::Mei(parse_opencv_omnidir(text)?)),
        OpencvModel::Pinhole => {
            let (k, k_name, d, d_name) = opencv_k_d(&doc)?;
            // OpenCV writes 4, 5, 8, 12 or 14 coefficients; the model has the first 5.
            if !(4..=14).contains(&d.len()) || d.iter().skip(5).any(|x| *x != 0.0) {
                return Err(format!(
                    "{d_name}: expected k1 k2 p1 p2 [k3] (4 or 5 numbers; the rational, thin-prism and tilt terms must be 0), got {d:?}"
                ));
            }
            let at = |i: usize| d.get(i).copied().unwrap_or(0.0);
            let (w, h) = (doc.number("image_width")?, doc.number("image_height")?);
            let v = [k[0], k[4], k[2], k[5], at(0), at(1), at(2), at(3), at(4)];
            pinhole_from(&v, w, h).map(CameraSpec::Pinhole).map_err(|e| format!("{k_name}/{d_name}: {e}"))
        }
        OpencvModel::Fisheye => {
            let (k, k_name, d, d_name) = opencv_k_d(&doc)?;
            if d.len() != 4 {
                return Err(format!("{d_name}: expected k1 k2 k3 k4 (4 numbers), got {}", d.len()));
            }
            let (w, h) = (doc.number("image_width")?, doc.number("image_height")?);
            let v = [k[0], k[4], k[2], k[5], d[0], d[1], d[2], d[3]];
            fisheye_from(&v, w, h).map(CameraSpec::Fisheye).map_err(|e| format!("{k_name}/{d_name}: {e}"))
        }
        OpencvModel::Auto => unreachable!("resolved above"),
    }
}

/// K (or camera_matrix), without skew, and D (or distortion_coefficients): (K, its name, D,
/// its name).
fn opencv_k_d(doc: &yaml::FlatYaml) -> Result<(Vec<f64>, String, Vec<f64>, String), String> {
    let either = |a: &str, b: &str| if doc.has_prefix(a) { a.to_string() } else { b.to_string() };
    let k_name = either("K", "camera_matrix");
    let d_name = either("D", "distortion_coefficients");
    let k = doc.matrix(&k_name, Some(9))?;
    let d = doc.matrix(&d_name, None)?;
    let skew_ok = k[1].abs() <= 1e-9 * k[0].abs();
    let rest_ok = k[3] == 0.0 && k[6] == 0.0 && k[7] == 0.0 && k[8] == 1.0;
    if !skew_ok || !rest_ok {
        return Err(format!("{k_name}: expected [fx, 0, cx, 0, fy, cy, 0, 0, 1] (no skew), got {k:?}"));
    }
    Ok((k, k_name, d, d_name))
}

/// Reads an OpenCV `cv::omnidir` YAML file: `K` (or `camera_matrix`), `D` (or
/// `distortion_coefficients`: k1 k2 p1 p2), `xi` (a 1 × 1 matrix or a number) and
/// `image_width`/`image_height`. K must have no skew (the Mei model has none).
pub fn parse_opencv_omnidir(text: &str) -> Result<MeiParams, String> {
    let doc = yaml::FlatYaml::parse(text)?;
    let either = |a: &str, b: &str| if doc.has_prefix(a) { a.to_string() } else { b.to_string() };
    let k_name = either("K", "camera_matrix");
    let d_name = either("D", "distortion_coefficients");
    let k = doc.matrix(&k_name, Some(9))?;
    let d = doc.matrix(&d_name, Some(4))?;
    let xi = if doc.has_prefix("xi.data") { doc.matrix("xi", Some(1))?[0] } else { doc.number("xi")? };
    let skew_ok = k[1].abs() <= 1e-9 * k[0].abs();
    let rest_ok = k[3] == 0.0 && k[6] == 0.0 && k[7] == 0.0 && k[8] == 1.0;
    if !skew_ok || !rest_ok {
        return Err(format!(
            "{k_name}: expected [fx, 0, cx, 0, fy, cy, 0, 0, 1] (no skew), got {k:?}; the Mei model has no skew"
        ));
    }
    let (w, h) = (doc.number("image_width")?, doc.number("image_height")?);
    mei_from([xi, k[0], k[4], k[2], k[5], d[0], d[1], d[2], d[3]], w, h)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::receiver::ordinary_tests::{fisheye_truth, pinhole_truth};
    use omni_model::{CameraModel, MeiCamera, OcamCamera};

    fn ocam_sample() -> OcamParams {
        OcamParams {
            poly: vec![-190.0, 0.0, 2.2e-3, -2.5e-6, 6.0e-9],
            inv_poly: vec![],
            cx_px: 380.25,
            cy_px: 241.5,
            c: 1.0003,
            d: 1e-4,
            e: -2e-4,
            width: 752,
            height: 480,
            inner_radius_px: 30.0,
            outer_radius_px: 235.0,
            viewpoint_mm: [0.0; 3],
        }
    }

    fn mei_sample() -> MeiParams {
        MeiParams {
            xi: 0.93,
            fx_px: 310.5,
            fy_px: 311.25,
            cx_px: 377.1,
            cy_px: 239.7,
            k1: -0.21,
            k2: 0.034,
            p1: 1.2e-3,
            p2: -7e-4,
            width: 752,
            height: 480,
            inner_radius_px: 0.0,
            outer_radius_px: 0.0,
            viewpoint_mm: [0.0; 3],
        }
    }

    #[test]
    fn ocam_export_import_round_trips_rays() {
        let p = ocam_sample();
        let (text, fit) = ocam_calib_results(&p);
        let (q, origin) = parse_ocam_calib_results(&text).unwrap();
        assert_eq!(origin, CentreOrigin::Zero);
        assert_eq!((q.cx_px, q.cy_px), (p.cx_px, p.cy_px), "the centre is written 0-based and read back unchanged");
        assert!(text.contains("\n241.5 380.25\n"), "{text}");
        let (a, b) = (OcamCamera::new(p).unwrap(), OcamCamera::new(q.clone()).unwrap());
        assert_eq!(q.inv_poly.len(), fit.degree + 1);
        for &(x, y) in &[(300.0, 100.0), (600.0, 300.0), (380.0, 50.0)] {
            let px = omni_geom::Vector2::new(x, y);
            let (ra, rb) = (a.pixel_to_ray(&px).unwrap(), b.pixel_to_ray(&px).unwrap());
            // Shortest round-trip numbers in the file: the same rays to rounding.
            assert!(ra.dir.angle(&rb.dir) < 1e-12, "{}", ra.dir.angle(&rb.dir));
        }
        assert!(parse_ocam_calib_results("5 1 2\n").unwrap_err().contains("expected 5 data lines"));
        let bad = text.replacen("-1.9e2", "x", 1);
        assert!(parse_ocam_calib_results(&bad).unwrap_err().contains("direct polynomial"), "{bad}");
    }

    #[test]
    fn ocam_inverse_polynomial_is_fitted_over_the_annulus_to_a_hundredth_of_a_pixel() {
        let p = ocam_sample();
        let (text, fit) = ocam_calib_results(&p);
        assert_eq!(fit.rho_range_px, [30.0, 235.0]);
        assert!(fit.max_error_px <= INVERSE_TOLERANCE_PX, "{fit:?}");
        assert!(text.contains(&format!("inverse polynomial of degree {} within", fit.degree)), "{text}");
        let (q, _) = parse_ocam_calib_results(&text).unwrap();
        // Independent check of the written coefficients: world2cam(cam2world(ρ)) = ρ over the
        // annulus, evaluated here as OCamCalib documents it (θ = atan(z / √(x² + y²))).
        let eval = |c: &[f64], x: f64| c.iter().rev().fold(0.0, |acc, k| acc * x + k);
        let worst = (0..=500)
            .map(|k| 30.0 + 205.0 * k as f64 / 500.0)
            .map(|rho| (eval(&q.inv_poly, (eval(&q.poly, rho) / rho).atan()) - rho).abs())
            .fold(0.0, f64::max);
        assert!(worst <= 0.01, "{worst}");
        // Without an annulus: out to the nearest image edge (row 241.5 of 480 → 238 px), not the diagonal.
        let mut open = ocam_sample();
        open.outer_radius_px = 0.0;
        open.inner_radius_px = 0.0;
        assert_eq!(ocam_calib_results(&open).1.rho_range_px, [0.0, 238.0]);
    }

    fn genuine_layout() -> String {
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../../testdata/ocam/calib_results_v3.txt");
        std::fs::read_to_string(path).unwrap()
    }

    #[test]
    fn ocam_v3_centre_imports_unchanged_and_older_headers_are_one_based() {
        let (p, origin) = parse_ocam_calib_results(&genuine_layout()).unwrap();
        assert_eq!(origin, CentreOrigin::Zero);
        assert_eq!((p.cy_px, p.cx_px), (241.019976, 385.783141));
        assert_eq!((p.width, p.height), (748, 480));
        let old = genuine_layout().replace(
            "#center: \"row\" and \"column\", starting from 0 (C convention)",
            "#center: \"row\" and \"column\" coordinates (x and y coordinates) of the center of the image",
        );
        let (q, origin) = parse_ocam_calib_results(&old).unwrap();
        assert_eq!(origin, CentreOrigin::One);
        assert!((q.cy_px - 240.019976).abs() < 1e-9 && (q.cx_px - 384.783141).abs() < 1e-9);
        let unknown = genuine_layout().replace("#center: \"row\" and \"column\", starting from 0 (C convention)", "");
        assert!(parse_ocam_calib_results(&unknown).unwrap_err().contains("its pixel origin is unknown"));
        let direct = "5 -1.953000e+02 0.000000e+00";
        let positive_a0 = genuine_layout().replace(direct, "5 0 0.000000e+00");
        let e = parse_ocam_calib_results(&positive_a0).unwrap_err();
        assert!(e.contains("poly[0] (a0) must be negative, got 0") && !e.contains("Some"), "{e}");
        let negative_count = genuine_layout().replace(direct, "-5 -1.953000e+02 0.000000e+00");
        let e = parse_ocam_calib_results(&negative_count).unwrap_err();
        assert!(e.contains("the count of coefficients is -5, not a whole number"), "{e}");
    }

    #[test]
    fn kalibr_export_has_topic_overlaps_and_frame_and_reads_back() {
        let p = mei_sample();
        let text = kalibr_camchain(&p, "/cam/left");
        for needed in
            ["rostopic: /cam/left", "cam_overlaps: []", "(x, y, -z) of the omniscan world", "camera_model: omni"]
        {
            assert!(text.contains(needed), "{needed} missing in {text}");
        }
        assert_eq!(parse_kalibr_camera(&text, "cam0").unwrap(), CameraSpec::Mei(p.clone()));
        let pinhole = text.replace("camera_model: omni", "camera_model: pinhole");
        assert!(
            parse_kalibr_camera(&pinhole, "cam0").unwrap_err().contains("cam0.intrinsics: expected 4 numbers, got 5")
        );
        let ds = text.replace("camera_model: omni", "camera_model: ds");
        assert_eq!(
            parse_kalibr_camera(&ds, "cam0").unwrap_err(),
            "cam0.camera_model: \"ds\" is not read (omni or pinhole)"
        );
        let equi = text.replace("distortion_model: radtan", "distortion_model: equidistant");
        assert!(parse_kalibr_camera(&equi, "cam0").unwrap_err().contains("\"equidistant\" is not read with omni"));
        assert!(
            parse_kalibr_camera(&text, "cam1").unwrap_err().contains("no camera \"cam1\" in the file (it has: cam0)")
        );
        let short = text.replace("resolution: [752, 480]", "resolution: [752]");
        assert!(parse_kalibr_camera(&short, "cam0").unwrap_err().contains("cam0.resolution: expected 2 numbers"));
    }

    #[test]
    fn yaml_floats_are_what_pyyaml_reads_as_floats_and_read_back_exactly() {
        for (x, text) in [(241.67485968203013, "2.4167485968203013e+2"), (80.0, "8.0e+1"), (0.0, "0.0e+0")] {
            assert_eq!(yaml_float(x), text);
        }
        assert_eq!(yaml_float(-6.346596602367157e-6), "-6.346596602367157e-6");
        // PyYAML's float pattern (YAML 1.1): a point, then an exponent with its sign.
        for x in [1.0, -2.5e-300, 123456.789, f64::MAX, f64::MIN_POSITIVE] {
            let t = yaml_float(x);
            let (mantissa, exponent) = t.split_once('e').unwrap();
            assert!(mantissa.contains('.') && exponent.starts_with(['+', '-']), "{t}");
            assert_eq!(t.parse::<f64>().unwrap(), x);
        }
    }

    #[test]
    fn exports_keep_the_viewpoint_and_the_annulus_for_their_import() {
        let p = MeiParams { viewpoint_mm: [1.5, -2.0, 80.0], ..mei_sample() };
        assert_eq!(viewpoint_in(&opencv_omnidir_yaml(&p), "").unwrap(), Some(p.viewpoint_mm));
        assert_eq!(viewpoint_in(&kalibr_camchain(&p, DEFAULT_ROSTOPIC), "cam0.").unwrap(), Some(p.viewpoint_mm));
        assert_eq!(viewpoint_in("%YAML:1.0\n---\nxi: 1.0\n", "").unwrap(), None);
        let o = OcamParams {
            viewpoint_mm: [0.0, 0.0, 80.0],
            inner_radius_px: 90.0,
            outer_radius_px: 400.0,
            ..ocam_sample()
        };
        let (q, _) = parse_ocam_calib_results(&ocam_calib_results(&o).0).unwrap();
        assert_eq!((q.viewpoint_mm, q.inner_radius_px, q.outer_radius_px), ([0.0, 0.0, 80.0], 90.0, 400.0));
    }

    #[test]
    fn opencv_export_reads_back_and_skew_is_refused() {
        let p = mei_sample();
        let text = opencv_omnidir_yaml(&p);
        assert!(text.contains("(x, y, -z) of the omniscan world"), "{text}");
        let q = parse_opencv_omnidir(&text).unwrap();
        assert_eq!(q, p);
        let cam = MeiCamera::new(q).unwrap();
        assert!(cam.pixel_to_ray(&omni_geom::Vector2::new(500.0, 300.0)).is_some());
        let skewed = text.replacen("data: [ 3.105e+2, 0.0e+0,", "data: [ 3.105e+2, 0.5,", 1);
        assert_ne!(skewed, text);
        assert!(parse_opencv_omnidir(&skewed).unwrap_err().contains("no skew"), "{skewed}");
        let no_size = text.replace("image_width: 752\n", "");
        assert_eq!(parse_opencv_omnidir(&no_size).unwrap_err(), "image_width: missing");
    }

    #[test]
    fn ordinary_cameras_read_back_from_opencv_and_kalibr_files() {
        let pinhole = CameraSpec::Pinhole(pinhole_truth());
        let fisheye = CameraSpec::Fisheye(fisheye_truth());
        let text = opencv_yaml_of(&pinhole).unwrap();
        assert!(
            text.contains("camera_matrix: !!opencv-matrix") && text.contains("(x, y, -z) of the omniscan"),
            "{text}"
        );
        assert_eq!(parse_opencv(&text, OpencvModel::Auto).unwrap(), pinhole);
        let text = opencv_yaml_of(&fisheye).unwrap();
        assert_eq!(parse_opencv(&text, OpencvModel::Fisheye).unwrap(), fisheye);
        assert!(parse_opencv(&text, OpencvModel::Auto).unwrap_err().contains("--model pinhole or fisheye"));
        // K and D of 4 read as a pinhole are the pinhole k1 k2 p1 p2.
        let CameraSpec::Pinhole(p) = parse_opencv(&text, OpencvModel::Pinhole).unwrap() else { panic!() };
        assert_eq!((p.k1, p.p2, p.k3), (-0.0352, -0.0158, 0.0));
        // Kalibr: pinhole + radtan needs k3 = 0; pinhole + equidistant is the fisheye.
        assert!(kalibr_camchain_of(&pinhole, "/t").unwrap_err().contains("Kalibr's radtan has no k3"));
        let radtan = CameraSpec::Pinhole(PinholeParams { k3: 0.0, ..pinhole_truth() });
        let chain = kalibr_camchain_of(&radtan, "/t").unwrap();
        assert!(chain.contains("camera_model: pinhole") && chain.contains("distortion_model: radtan"), "{chain}");
        assert_eq!(parse_kalibr_camera(&chain, "cam0").unwrap(), radtan);
        let chain = kalibr_camchain_of(&fisheye, "/t").unwrap();
        assert!(chain.contains("distortion_model: equidistant"), "{chain}");
        assert_eq!(parse_kalibr_camera(&chain, "cam0").unwrap(), fisheye);
        let hyperbolic = CameraSpec::Hyperbolic(omni_model::HyperbolicParams::paper());
        let refused = "needs a camera of kind mei, pinhole or fisheye, this one is hyperbolic";
        assert_eq!(opencv_yaml_of(&hyperbolic).unwrap_err(), refused);
    }

    #[test]
    fn opencv_rational_coefficients_are_refused_unless_zero() {
        let text = opencv_pinhole_yaml(&pinhole_truth());
        let eight = text.replace("rows: 5", "rows: 8").replace("-1.92e-2 ]", "-1.92e-2, 0., 0., 0. ]");
        assert_eq!(parse_opencv(&eight, OpencvModel::Auto).unwrap(), CameraSpec::Pinhole(pinhole_truth()), "{eight}");
        let rational = eight.replace("-1.92e-2, 0.,", "-1.92e-2, 0.5,");
        assert!(parse_opencv(&rational, OpencvModel::Auto).unwrap_err().contains("rational"), "{rational}");
    }
}
