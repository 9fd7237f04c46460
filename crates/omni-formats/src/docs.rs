//! Description files: camera, scanner (transmitter), checkerboard.

use crate::{Error, Result, Versioned};
use omni_model::{
    CameraColour, CameraModel, FisheyeCamera, FisheyeParams, FixedPlanes, FixedPlanesParams, HyperbolicCamera,
    HyperbolicParams, MeiCamera, MeiParams, OcamCamera, OcamParams, Optics, PinholeCamera, PinholeParams,
    TRANSMITTER_KIND_FIXED_PLANES, TRANSMITTER_KIND_POLYGON, Transmitter, TransmitterModel, TransmitterParams,
};
use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// The camera model stored in `camera.json`, tagged by `kind`.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(tag = "kind", rename_all = "lowercase")]
pub enum CameraSpec {
    /// The exact hyperbolic mirror + pinhole model (SENSOR.md).
    Hyperbolic(HyperbolicParams),
    /// Mei's unified model with radial-tangential distortion (omni_model::mei).
    Mei(MeiParams),
    /// Scaramuzza's polynomial model, OCamCalib (omni_model::ocam).
    Ocam(OcamParams),
    /// An ordinary camera: pinhole with radial-tangential distortion, as OpenCV's
    /// `calibrateCamera` and Kalibr's `pinhole-radtan` (omni_model::pinhole).
    Pinhole(PinholeParams),
    /// An ordinary fisheye camera: Kannala–Brandt, as OpenCV's `cv::fisheye` and Kalibr's
    /// `pinhole-equi` (omni_model::fisheye).
    Fisheye(FisheyeParams),
}

/// A model's parameters (its `kind` taken out), with errors naming the parameter at fault; a
/// missing one is named by serde's message alone (its path is the object itself, `.`).
fn kind_params<T: DeserializeOwned, E: serde::de::Error>(v: serde_json::Value) -> std::result::Result<T, E> {
    serde_path_to_error::deserialize(v).map_err(|e| match e.path().to_string().as_str() {
        "." => E::custom(e.inner()),
        path => E::custom(format!("field {path}: {}", e.inner())),
    })
}

/// Deserialises `{"kind": K, ...params}` by hand so that errors name the exact parameter
/// (serde's internally tagged enums lose the field path).
impl<'de> Deserialize<'de> for CameraSpec {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> std::result::Result<Self, D::Error> {
        use serde::de::Error as _;
        let mut map = serde_json::Map::<String, serde_json::Value>::deserialize(d)?;
        let kind = map.remove("kind").ok_or_else(|| D::Error::missing_field("kind"))?;
        let kind = kind.as_str().ok_or_else(|| D::Error::custom("field kind: expected a string"))?.to_string();
        let rest = serde_json::Value::Object(map);
        match kind.as_str() {
            "hyperbolic" => Ok(CameraSpec::Hyperbolic(kind_params(rest)?)),
            "mei" => Ok(CameraSpec::Mei(kind_params(rest)?)),
            "ocam" => Ok(CameraSpec::Ocam(kind_params(rest)?)),
            "pinhole" => Ok(CameraSpec::Pinhole(kind_params(rest)?)),
            "fisheye" => Ok(CameraSpec::Fisheye(kind_params(rest)?)),
            other => Err(D::Error::custom(format!(
                "unknown camera model kind \"{other}\" (known: hyperbolic, mei, ocam, pinhole, fisheye)"
            ))),
        }
    }
}

impl CameraSpec {
    /// Builds the usable model; the error names the invalid field.
    pub fn build(&self) -> std::result::Result<Box<dyn CameraModel>, String> {
        match self {
            CameraSpec::Hyperbolic(p) => Ok(Box::new(HyperbolicCamera::new(p.clone())?)),
            CameraSpec::Mei(p) => Ok(Box::new(MeiCamera::new(p.clone())?)),
            CameraSpec::Ocam(p) => Ok(Box::new(OcamCamera::new(p.clone())?)),
            CameraSpec::Pinhole(p) => Ok(Box::new(PinholeCamera::new(p.clone())?)),
            CameraSpec::Fisheye(p) => Ok(Box::new(FisheyeCamera::new(p.clone())?)),
        }
    }

    /// Where the model's rays start (mm, world frame): the generic models' `viewpoint_mm`, the
    /// exact hyperbolic camera's upper mirror focus (0, 0, 2c).
    pub fn viewpoint_mm(&self) -> [f64; 3] {
        match self {
            CameraSpec::Hyperbolic(h) => [0.0, 0.0, 2.0 * h.a_mm.hypot(h.b_mm)],
            CameraSpec::Mei(p) => p.viewpoint_mm,
            CameraSpec::Ocam(p) => p.viewpoint_mm,
            CameraSpec::Pinhole(p) => p.viewpoint_mm,
            CameraSpec::Fisheye(p) => p.viewpoint_mm,
        }
    }

    /// Places a generic model's viewpoint (mm, world frame); the exact hyperbolic model keeps its
    /// own (its mirror fixes it).
    pub fn set_viewpoint_mm(&mut self, viewpoint: [f64; 3]) {
        match self {
            CameraSpec::Hyperbolic(_) => {}
            CameraSpec::Mei(p) => p.viewpoint_mm = viewpoint,
            CameraSpec::Ocam(p) => p.viewpoint_mm = viewpoint,
            CameraSpec::Pinhole(p) => p.viewpoint_mm = viewpoint,
            CameraSpec::Fisheye(p) => p.viewpoint_mm = viewpoint,
        }
    }

    /// The kind's name as the file writes it.
    pub fn kind(&self) -> &'static str {
        match self {
            CameraSpec::Hyperbolic(_) => "hyperbolic",
            CameraSpec::Mei(_) => "mei",
            CameraSpec::Ocam(_) => "ocam",
            CameraSpec::Pinhole(_) => "pinhole",
            CameraSpec::Fisheye(_) => "fisheye",
        }
    }
}

/// `camera.json`: a receiver model plus an optional calibration report.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CameraFile {
    pub format: String,
    pub version: u32,
    pub model: CameraSpec,
    /// The lens and sensor optics (wavelength, F-number, pixel pitch, defocus), where known: the
    /// simulator renders with them and `omni-eval budget` predicts noise from them.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub optics: Option<Optics>,
    /// The lens's blur as measured (Gaussian PSF σ, px, the pixel's area not included), e.g. by
    /// `omni-calib-receiver` on its boards' edges; the stripe detector removes its pull on curved
    /// stripes.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub lens_blur_px: Option<f64>,
    /// A colour camera's filters and processing (mosaic, responses, white balance, colour
    /// matrix); absent: a monochrome camera. The simulator renders colour frames from it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub colour: Option<CameraColour>,
    /// Free-form calibration report (residuals, uncertainties, images used).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub report: Option<serde_json::Value>,
}

impl Versioned for CameraFile {
    const FORMAT: &'static str = "omniscan.camera";
    const VERSION: u32 = 1;
}

impl CameraFile {
    pub fn new(model: CameraSpec) -> Self {
        CameraFile {
            format: Self::FORMAT.into(),
            version: Self::VERSION,
            model,
            optics: None,
            lens_blur_px: None,
            colour: None,
            report: None,
        }
    }

    /// The lens's blur (PSF σ, px) the stripe detector should remove: the measured one, else the
    /// one the optics imply; `None` if the file has neither, or its optics are focused at a
    /// distance (their blur varies over the image).
    pub fn lens_blur(&self) -> Option<f64> {
        self.lens_blur_px.or(self.optics.filter(|o| !o.field_dependent()).map(|o| o.psf_sigma_px()))
    }

    /// Reads and validates `camera.json`, returning the usable model.
    pub fn load(path: &Path) -> Result<(CameraFile, Box<dyn CameraModel>)> {
        let bytes = crate::io::read_all(path)?;
        Self::parse(&bytes, &crate::io::display_name(path, "stdin"))
    }

    /// Parses and validates `camera.json` from its bytes ([`load`](Self::load) without the
    /// file; the fuzzers use it); errors name `source_name`.
    pub fn parse(bytes: &[u8], source_name: &str) -> Result<(CameraFile, Box<dyn CameraModel>)> {
        let file: CameraFile = parse_doc(bytes, source_name)?;
        let model = file.model.build().map_err(|m| Error::new(source_name, "field model", m))?;
        if let Some(optics) = &file.optics {
            optics.validate().map_err(|m| Error::new(source_name, "field optics", m))?;
        }
        if let Some(colour) = &file.colour {
            colour.validate().map_err(|m| Error::new(source_name, "field colour", m))?;
        }
        if let Some(blur) = file.lens_blur_px
            && !(blur.is_finite() && blur > 0.0 && blur <= 5.0)
        {
            return Err(Error::new(source_name, "field lens_blur_px", format!("must be within (0, 5] px, got {blur}")));
        }
        Ok((file, model))
    }
}

/// The transmitter stored in `scanner.json`, tagged by `kind`: `polygon` (the rotating polygon
/// mirror, [`TransmitterParams`]) or `fixed_planes` (static light planes,
/// [`FixedPlanesParams`]). Version 1 files hold a polygon without a `kind`; a polygon is still
/// written that way (so that older builds read it), fixed planes with `kind` in version 2.
#[derive(Debug, Clone, PartialEq)]
pub enum TransmitterSpec {
    Polygon(TransmitterParams),
    FixedPlanes(FixedPlanesParams),
}

impl From<TransmitterParams> for TransmitterSpec {
    fn from(p: TransmitterParams) -> Self {
        TransmitterSpec::Polygon(p)
    }
}

impl From<FixedPlanesParams> for TransmitterSpec {
    fn from(p: FixedPlanesParams) -> Self {
        TransmitterSpec::FixedPlanes(p)
    }
}

impl TransmitterSpec {
    /// The kind's name as the file writes it.
    pub fn kind(&self) -> &'static str {
        match self {
            TransmitterSpec::Polygon(_) => TRANSMITTER_KIND_POLYGON,
            TransmitterSpec::FixedPlanes(_) => TRANSMITTER_KIND_FIXED_PLANES,
        }
    }

    /// The polygon's parameters, if that is the kind.
    pub fn polygon(&self) -> Option<&TransmitterParams> {
        match self {
            TransmitterSpec::Polygon(p) => Some(p),
            TransmitterSpec::FixedPlanes(_) => None,
        }
    }

    /// Builds the usable model; the error names the invalid field.
    pub fn build(&self) -> std::result::Result<TransmitterModel, String> {
        match self {
            TransmitterSpec::Polygon(p) => Ok(TransmitterModel::Polygon(Transmitter::new(p.clone())?)),
            TransmitterSpec::FixedPlanes(p) => Ok(TransmitterModel::FixedPlanes(FixedPlanes::new(p.clone())?)),
        }
    }
}

impl Serialize for TransmitterSpec {
    fn serialize<S: serde::Serializer>(&self, s: S) -> std::result::Result<S::Ok, S::Error> {
        use serde::ser::SerializeMap;
        match self {
            // Version 1's layout, unchanged: no kind.
            TransmitterSpec::Polygon(p) => p.serialize(s),
            TransmitterSpec::FixedPlanes(p) => {
                let mut m = s.serialize_map(Some(2))?;
                m.serialize_entry("kind", TRANSMITTER_KIND_FIXED_PLANES)?;
                m.serialize_entry("planes", &p.planes)?;
                m.end()
            }
        }
    }
}

/// Deserialises `{"kind": K, ...params}` by hand so that errors name the exact parameter; no
/// `kind` is a polygon (version 1).
impl<'de> Deserialize<'de> for TransmitterSpec {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> std::result::Result<Self, D::Error> {
        use serde::de::Error as _;
        let mut map = serde_json::Map::<String, serde_json::Value>::deserialize(d)?;
        let kind = match map.remove("kind") {
            None => TRANSMITTER_KIND_POLYGON.to_string(),
            Some(k) => k.as_str().ok_or_else(|| D::Error::custom("field kind: expected a string"))?.to_string(),
        };
        let rest = serde_json::Value::Object(map);
        match kind.as_str() {
            TRANSMITTER_KIND_POLYGON => Ok(TransmitterSpec::Polygon(kind_params(rest)?)),
            TRANSMITTER_KIND_FIXED_PLANES => Ok(TransmitterSpec::FixedPlanes(kind_params(rest)?)),
            other => Err(D::Error::custom(format!(
                "field kind: unknown transmitter kind \"{other}\" (known: {TRANSMITTER_KIND_POLYGON}, {TRANSMITTER_KIND_FIXED_PLANES})"
            ))),
        }
    }
}

/// `scanner.json`: the transmitter model plus an optional calibration report.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ScannerFile {
    pub format: String,
    pub version: u32,
    pub transmitter: TransmitterSpec,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub report: Option<serde_json::Value>,
}

impl Versioned for ScannerFile {
    const FORMAT: &'static str = "omniscan.scanner";
    /// Version 2 added `transmitter.kind` (fixed planes); version 1 (a polygon) is still read.
    const VERSION: u32 = 2;
    const MIN_VERSION: u32 = 1;
}

/// The facet and laser indices of a light-plane calibration report's `model.fixed` entries that
/// say "not observed" (`facet_errors[k]: …`, `lasers[j]: …`), in their order.
pub fn unobserved_in<'a>(fixed: impl IntoIterator<Item = &'a str>) -> (Vec<u32>, Vec<u32>) {
    let entries: Vec<&str> = fixed.into_iter().filter(|e| e.contains("not observed")).collect();
    let indices = |prefix: &str| -> Vec<u32> {
        entries.iter().filter_map(|e| e.strip_prefix(prefix)?.split(']').next()?.parse().ok()).collect()
    };
    (indices("facet_errors["), indices("lasers["))
}

impl ScannerFile {
    /// The facets and lasers the light-plane calibration never saw, and so kept at their
    /// initial values: its report's `model.fixed` entries `facet_errors[k]: … not observed` and
    /// `lasers[j]: … not observed` (both empty without a report).
    pub fn unobserved(&self) -> (Vec<u32>, Vec<u32>) {
        let fixed = self.report.as_ref().and_then(|r| r.pointer("/model/fixed")).and_then(|f| f.as_array());
        unobserved_in(fixed.into_iter().flatten().filter_map(|e| e.as_str()))
    }

    /// A file holding `transmitter`: version 1 for a polygon (the layout older builds read),
    /// version 2 for fixed planes.
    pub fn new(transmitter: impl Into<TransmitterSpec>) -> Self {
        let transmitter = transmitter.into();
        let version = match transmitter {
            TransmitterSpec::Polygon(_) => 1,
            TransmitterSpec::FixedPlanes(_) => 2,
        };
        ScannerFile { format: Self::FORMAT.into(), version, transmitter, report: None }
    }

    /// Reads and validates `scanner.json`, returning the usable model (either kind).
    pub fn load(path: &Path) -> Result<(ScannerFile, TransmitterModel)> {
        let bytes = crate::io::read_all(path)?;
        Self::parse(&bytes, &crate::io::display_name(path, "stdin"))
    }

    /// Parses and validates `scanner.json` from its bytes ([`load`](Self::load) without the
    /// file; the fuzzers use it); errors name `source_name`.
    pub fn parse(bytes: &[u8], source_name: &str) -> Result<(ScannerFile, TransmitterModel)> {
        let file: ScannerFile = parse_doc(bytes, source_name)?;
        if file.version == 1 && !matches!(file.transmitter, TransmitterSpec::Polygon(_)) {
            return Err(Error::new(
                source_name,
                "field transmitter.kind",
                format!("\"{}\" needs version 2 (version 1 holds a polygon)", file.transmitter.kind()),
            ));
        }
        let model = file.transmitter.build().map_err(|m| Error::new(source_name, "field transmitter", m))?;
        Ok((file, model))
    }

    /// [`load`](Self::load) for a tool that needs the rotating polygon: another kind is a
    /// one-line error naming it.
    pub fn load_polygon(path: &Path) -> Result<(ScannerFile, Transmitter)> {
        let bytes = crate::io::read_all(path)?;
        Self::parse_polygon(&bytes, &crate::io::display_name(path, "stdin"))
    }

    /// [`parse`](Self::parse) for a tool that needs the rotating polygon.
    pub fn parse_polygon(bytes: &[u8], source_name: &str) -> Result<(ScannerFile, Transmitter)> {
        let (file, model) = Self::parse(bytes, source_name)?;
        match model {
            TransmitterModel::Polygon(t) => Ok((file, t)),
            other => Err(not_polygon(source_name, other.kind())),
        }
    }
}

/// The error of a tool that needs a polygon transmitter and got another kind.
pub fn not_polygon(source_name: &str, kind: &str) -> Error {
    Error::new(
        source_name,
        "field transmitter.kind",
        format!(
            "transmitter kind \"{kind}\" cannot be used here: this needs kind \"{TRANSMITTER_KIND_POLYGON}\" (the rotating polygon mirror)"
        ),
    )
}

/// `board.json`: a planar checkerboard.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BoardFile {
    pub format: String,
    pub version: u32,
    /// Inner corners along the board's x (columns).
    pub inner_cols: u32,
    /// Inner corners along the board's y (rows).
    pub inner_rows: u32,
    /// Square side (mm).
    pub square_mm: f64,
    /// White margin around the outer squares (mm).
    #[serde(default)]
    pub margin_mm: f64,
}

impl Versioned for BoardFile {
    const FORMAT: &'static str = "omniscan.board";
    const VERSION: u32 = 1;

    fn check(&self) -> std::result::Result<(), String> {
        self.validate()
    }
}

impl BoardFile {
    pub fn new(inner_cols: u32, inner_rows: u32, square_mm: f64) -> Self {
        BoardFile {
            format: Self::FORMAT.into(),
            version: Self::VERSION,
            inner_cols,
            inner_rows,
            square_mm,
            margin_mm: square_mm,
        }
    }

    /// Checks the board is usable; the message names the field.
    pub fn validate(&self) -> std::result::Result<(), String> {
        check_board_corners("", self.inner_cols, self.inner_rows)?;
        use omni_model::limits::{MAX_BOARD_EXTENT_MM, MIN_BOARD_SQUARE_MM, shown};
        if !(self.square_mm.is_finite() && self.square_mm > 0.0) {
            return Err(format!("square_mm must be positive, got {}", shown(self.square_mm)));
        }
        if self.square_mm < MIN_BOARD_SQUARE_MM {
            return Err(format!("square_mm must be at least {MIN_BOARD_SQUARE_MM} mm, got {}", shown(self.square_mm)));
        }
        if !(self.margin_mm.is_finite() && self.margin_mm >= 0.0) {
            return Err(format!("margin_mm must be non-negative, got {}", shown(self.margin_mm)));
        }
        let squares = f64::from(self.inner_cols.max(self.inner_rows) + 1);
        let extent = squares * self.square_mm + 2.0 * self.margin_mm;
        if extent > MAX_BOARD_EXTENT_MM {
            return Err(format!(
                "square_mm / margin_mm: the board would be {} mm across, more than {MAX_BOARD_EXTENT_MM} mm",
                shown(extent)
            ));
        }
        Ok(())
    }
}

/// Checks a board's inner corner counts: at least 2, at most
/// [`omni_model::limits::MAX_BOARD_CORNERS`] per side. `prefix` is the field path to the board
/// (`""` for board.json, `"boards[1]."` in a rig).
pub(crate) fn check_board_corners(prefix: &str, cols: u32, rows: u32) -> std::result::Result<(), String> {
    let max = omni_model::limits::MAX_BOARD_CORNERS;
    for (name, v) in [("inner_cols", cols), ("inner_rows", rows)] {
        if !(2..=max).contains(&v) {
            return Err(format!("field {prefix}{name}: must be in 2..={max}, got {v}"));
        }
    }
    Ok(())
}

/// Parses a versioned JSON document from text, checking `format` and `version` first so that a
/// file of the wrong kind or a newer version gets a clear message rather than a field error.
pub fn parse_doc<T: DeserializeOwned + Versioned>(text: &[u8], source_name: &str) -> Result<T> {
    let value: serde_json::Value = serde_json::from_slice(text).map_err(|e| {
        Error::new(source_name, format!("line {} column {}", e.line(), e.column()), format!("invalid JSON: {e}"))
    })?;
    check_header_versions(&value, T::FORMAT, T::MIN_VERSION, T::VERSION, source_name)?;
    let doc: T = serde_path_to_error::deserialize(value).map_err(|e| {
        let path = e.path().to_string();
        Error::new(
            source_name,
            if path == "." { String::new() } else { format!("field {path}") },
            e.into_inner().to_string(),
        )
    })?;
    doc.check().map_err(|m| Error::new(source_name, "", m))?;
    Ok(doc)
}

/// Checks a JSON object's `format` and `version` fields.
pub(crate) fn check_header(value: &serde_json::Value, format: &str, version: u32, source_name: &str) -> Result<()> {
    check_header_versions(value, format, version, version, source_name)
}

/// Checks a JSON object's `format` and that its `version` is within `min_version..=version`.
pub(crate) fn check_header_versions(
    value: &serde_json::Value,
    format: &str,
    min_version: u32,
    version: u32,
    source_name: &str,
) -> Result<()> {
    let obj = value.as_object().ok_or_else(|| Error::new(source_name, "", "expected a JSON object"))?;
    match obj.get("format").and_then(|f| f.as_str()) {
        None => return Err(Error::new(source_name, "field format", format!("missing (expected \"{format}\")"))),
        Some(f) if f != format => {
            return Err(Error::new(source_name, "field format", format!("is \"{f}\", expected \"{format}\"")));
        }
        _ => {}
    }
    match obj.get("version").and_then(|v| v.as_u64()) {
        None => Err(Error::new(source_name, "field version", "missing or not an integer")),
        Some(v) if !(min_version as u64..=version as u64).contains(&v) => Err(Error::new(
            source_name,
            "field version",
            if min_version == version {
                format!("unsupported version {v} (this build reads version {version})")
            } else {
                format!("unsupported version {v} (this build reads versions {min_version} to {version})")
            },
        )),
        _ => Ok(()),
    }
}

/// Reads a versioned JSON document from a file (`-` = stdin).
pub fn read_doc<T: DeserializeOwned + Versioned>(path: &Path) -> Result<T> {
    let bytes = crate::io::read_all(path)?;
    parse_doc(&bytes, &crate::io::display_name(path, "stdin"))
}

/// Writes a document as pretty JSON, atomically (`-` = stdout).
pub fn write_doc<T: Serialize>(path: &Path, doc: &T) -> Result<()> {
    stage_doc(path, doc)?.commit()
}

/// [`write_doc`] up to the rename ([`crate::io::write_staged`]).
pub fn stage_doc<T: Serialize>(path: &Path, doc: &T) -> Result<crate::io::Staged> {
    crate::io::write_staged(path, |w| {
        serde_json::to_writer_pretty(&mut *w, doc).map_err(std::io::Error::other)?;
        w.write_all(b"\n")
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn camera_json() -> serde_json::Value {
        serde_json::to_value(CameraFile::new(CameraSpec::Hyperbolic(HyperbolicParams::paper()))).unwrap()
    }

    fn parse(v: &serde_json::Value) -> Result<CameraFile> {
        parse_doc(&serde_json::to_vec(v).unwrap(), "camera.json")
    }

    #[test]
    fn camera_round_trips() {
        let v = camera_json();
        assert_eq!(v["model"]["kind"], "hyperbolic");
        let f = parse(&v).unwrap();
        assert_eq!(serde_json::to_value(&f).unwrap(), v);
    }

    #[test]
    fn wrong_version_missing_field_and_nan_are_named() {
        let mut v = camera_json();
        v["version"] = 2.into();
        let e = parse(&v).unwrap_err().to_string();
        assert!(e.contains("unsupported version 2"), "{e}");

        let mut v = camera_json();
        v["model"].as_object_mut().unwrap().remove("a_mm");
        let e = parse(&v).unwrap_err().to_string();
        assert!(e.contains("field model: missing field `a_mm`"), "{e}");

        let text = serde_json::to_string(&camera_json()).unwrap().replace("\"fx_px\":1950.0", "\"fx_px\":NaN");
        let e = parse_doc::<CameraFile>(text.as_bytes(), "camera.json").unwrap_err().to_string();
        assert!(e.starts_with("camera.json: line 1"), "{e}");

        let mut v = camera_json();
        v["model"]["fx_px"] = serde_json::Value::Null;
        let e = parse(&v).unwrap_err().to_string();
        assert!(e.contains("fx_px"), "{e}");

        let mut v = camera_json();
        v["format"] = "omniscan.scanner".into();
        assert!(parse(&v).unwrap_err().to_string().contains("expected \"omniscan.camera\""));
    }

    #[test]
    fn invalid_values_are_refused_with_field_name() {
        let mut v = camera_json();
        v["model"]["rim_radius_mm"] = (-1.0).into();
        let f = parse(&v).unwrap();
        let e = f.model.build().unwrap_err();
        assert!(e.contains("rim_radius_mm"), "{e}");
    }

    #[test]
    fn board_sizes_are_bounded() {
        let mut v = serde_json::to_value(BoardFile::new(9, 6, 30.0)).unwrap();
        v["inner_cols"] = 100_000.into();
        let e = parse_doc::<BoardFile>(&serde_json::to_vec(&v).unwrap(), "board.json").unwrap_err().to_string();
        assert_eq!(e, "board.json: field inner_cols: must be in 2..=1000, got 100000");
        // Squares and margins: a micrometre at least, the whole board 100 m at most.
        for (field, value, expected) in [
            ("square_mm", 1e-300, "square_mm must be at least 0.001 mm, got 1e-300"),
            ("square_mm", 1e306, "the board would be 1e307 mm across"),
            ("margin_mm", 1e308, "the board would be inf mm across"),
        ] {
            let mut v = serde_json::to_value(BoardFile::new(9, 6, 30.0)).unwrap();
            v[field] = value.into();
            let e = parse_doc::<BoardFile>(&serde_json::to_vec(&v).unwrap(), "board.json").unwrap_err().to_string();
            assert!(e.starts_with("board.json: ") && e.contains(expected), "{field} {value}: {e}");
        }
    }

    #[test]
    fn camera_image_size_is_bounded() {
        let mut v = camera_json();
        v["model"]["width"] = 2_000_000_000u32.into();
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("camera.json");
        std::fs::write(&path, serde_json::to_vec(&v).unwrap()).unwrap();
        let e = CameraFile::load(&path).err().unwrap().to_string();
        assert!(e.contains("camera.json") && e.contains("field model") && e.contains("16384"), "{e}");
    }

    #[test]
    fn the_lens_blur_is_read_and_checked() {
        let parse = |v: &serde_json::Value| CameraFile::parse(&serde_json::to_vec(v).unwrap(), "camera.json");
        let mut v = camera_json();
        assert_eq!(parse(&v).unwrap().0.lens_blur(), None);
        v["optics"] = serde_json::to_value(Optics::paper()).unwrap();
        let from_optics = parse(&v).unwrap().0.lens_blur().unwrap();
        assert!((from_optics - Optics::paper().psf_sigma_px()).abs() < 1e-12);
        v["optics"]["defocus_px"] = 0.0.into();
        v["optics"]["focus_mm"] = 91.0.into();
        assert_eq!(parse(&v).unwrap().0.lens_blur(), None, "a blur varying over the image is not one figure");
        v["optics"]["defocus_px"] = 1.5.into();
        let e = parse(&v).err().unwrap().to_string();
        assert!(e.starts_with("camera.json: field optics: defocus_px (1.5) and focus_mm (91)"), "{e}");
        v["optics"]["focus_mm"] = serde_json::Value::Null;
        v["lens_blur_px"] = 0.6.into();
        assert_eq!(parse(&v).unwrap().0.lens_blur(), Some(0.6));
        v["lens_blur_px"] = (-1.0).into();
        let e = parse(&v).err().unwrap().to_string();
        assert_eq!(e, "camera.json: field lens_blur_px: must be within (0, 5] px, got -1");
    }

    fn scanner_parse(v: &serde_json::Value) -> Result<(ScannerFile, TransmitterModel)> {
        ScannerFile::parse(&serde_json::to_vec(v).unwrap(), "scanner.json")
    }

    fn fixed_json() -> serde_json::Value {
        serde_json::json!({"format": "omniscan.scanner", "version": 2,
            "transmitter": {"kind": "fixed_planes",
                "planes": [{"laser": 0, "normal": [0.0, 0.6, 0.8], "distance_mm": 120.0}]}})
    }

    #[test]
    fn scanner_kinds_and_versions() {
        // A version 1 file (no kind) is a polygon, written back unchanged.
        let v1 = serde_json::to_value(ScannerFile::new(TransmitterParams::paper())).unwrap();
        assert_eq!(v1["version"], 1);
        assert!(v1["transmitter"].get("kind").is_none());
        let (f, m) = scanner_parse(&v1).unwrap();
        assert_eq!(m.kind(), "polygon");
        assert_eq!(serde_json::to_value(&f).unwrap(), v1);
        // Version 2 with kind polygon reads too.
        let mut v2 = v1.clone();
        v2["version"] = 2.into();
        v2["transmitter"]["kind"] = "polygon".into();
        assert_eq!(scanner_parse(&v2).unwrap().1.kind(), "polygon");
        // Fixed planes: round trip, the plane as written.
        let (f, m) = scanner_parse(&fixed_json()).unwrap();
        assert_eq!(serde_json::to_value(&f).unwrap(), fixed_json());
        let TransmitterModel::FixedPlanes(fp) = m else { panic!("not fixed") };
        let p = fp.plane(0).unwrap();
        assert!((p.normal.y - 0.6).abs() < 1e-15 && (p.offset - 120.0).abs() < 1e-12);
        // Unknown kind, unknown version, fixed planes in version 1, bad plane: one line naming it.
        let mut v = fixed_json();
        v["transmitter"]["kind"] = "galvo".into();
        let e = scanner_parse(&v).unwrap_err().to_string();
        assert!(
            e.starts_with("scanner.json: field transmitter") && e.contains("unknown transmitter kind \"galvo\""),
            "{e}"
        );
        assert!(!e.contains('\n'));
        let mut v = fixed_json();
        v["version"] = 3.into();
        let e = scanner_parse(&v).unwrap_err().to_string();
        assert!(e.contains("unsupported version 3 (this build reads versions 1 to 2)"), "{e}");
        let mut v = fixed_json();
        v["version"] = 1.into();
        let e = scanner_parse(&v).unwrap_err().to_string();
        assert!(e.contains("field transmitter.kind") && e.contains("needs version 2"), "{e}");
        let mut v = fixed_json();
        v["transmitter"]["planes"][0]["normal"] = serde_json::json!([0, 0, 0]);
        let e = scanner_parse(&v).unwrap_err().to_string();
        assert!(e.contains("planes[0].normal"), "{e}");
        let mut v = fixed_json();
        v["transmitter"]["planes"][0]["offset"] = 1.into();
        let e = scanner_parse(&v).unwrap_err().to_string();
        assert!(e.contains("offset"), "{e}");
        // A tool that needs the polygon names the kind.
        let e = ScannerFile::parse_polygon(&serde_json::to_vec(&fixed_json()).unwrap(), "s.json").unwrap_err();
        assert_eq!(
            e.to_string(),
            "s.json: field transmitter.kind: transmitter kind \"fixed_planes\" cannot be used here: this needs kind \"polygon\" (the rotating polygon mirror)"
        );
    }
}
