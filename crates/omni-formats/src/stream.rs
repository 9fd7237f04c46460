//! The per-frame stream that flows between the tools: JSON Lines, one record per line.
//!
//! ```text
//! {"type":"header","format":"omniscan.stream","version":1,...}
//! {"type":"frame","seq":0,"path":"frames/000000.png","alpha_deg":0.5,"facet":0,...}
//! {"type":"frame","seq":1,...,"stripe":[[u,v,intensity,width,quality],...]}
//! {"type":"frame","seq":2,...,"points":[[x,y,z,laser,range,stripe_index],...]}
//! {"type":"status","frames":3,"frames_missing":0,"complete":true,...}
//! ```
//! Each tool adds its part to a frame record and passes every other field through untouched
//! (unknown fields are kept in `extra`). Point arrays are compact arrays of numbers.

use crate::{Error, Result};
use serde::{Deserialize, Serialize};
use std::io::{BufRead, Write};

/// The stream's `format` name and version.
pub const STREAM_FORMAT: &str = "omniscan.stream";
pub const STREAM_VERSION: u32 = 1;
/// The version of a stream whose frames may carry their arrays in binary (see
/// [`StreamWriter::binary`]); streams without them stay version 1, which every build reads.
pub const STREAM_BINARY_VERSION: u32 = 2;
/// The frame field that announces binary arrays after the record's line.
const BINARY_FIELD: &str = "binary";

/// One line of the stream.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "type", rename_all = "lowercase")]
pub enum Record {
    Header(Header),
    Frame(Box<Frame>),
    Status(Status),
    /// A per-frame failure reported with `--keep-going`.
    Error(FrameError),
}

/// First record: what the stream is and what produced it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Header {
    pub format: String,
    pub version: u32,
    /// Tools that have processed the stream, in order, e.g. `omni-trigger 0.1.0`.
    #[serde(default)]
    pub producers: Vec<String>,
    /// Directory that relative frame paths are resolved against: relative to the stream file's
    /// own directory when read with [`StreamReader::open`], else to the current one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub frames_dir: Option<String>,
    /// Sensor files the stream was made with, if known.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub camera: Option<String>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub scanner: Option<String>,
    /// Where the camera's rays start (mm, sensor frame): the point each frame's points were
    /// seen from, which their `range` is measured from and their normals face. Written by
    /// omni-triangulate; absent in streams without points (the sensor origin is assumed).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub viewpoint_mm: Option<[f64; 3]>,
    #[serde(flatten)]
    pub extra: serde_json::Map<String, serde_json::Value>,
}

impl Header {
    pub fn new(producer: &str) -> Self {
        Header {
            format: STREAM_FORMAT.into(),
            version: STREAM_VERSION,
            producers: vec![producer.into()],
            frames_dir: None,
            camera: None,
            scanner: None,
            viewpoint_mm: None,
            extra: Default::default(),
        }
    }
}

/// A stripe centre found in a frame: serialised as `[u, v, intensity, width, quality]`.
/// `u`, `v` are pixel coordinates (x right, y down, centre of top-left pixel = 0);
/// intensity is the peak (0–255 for 8-bit frames, 0–65535 for 16-bit); width in px;
/// quality is a bit set of [`quality`] flags (0 = good).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(try_from = "[f64; 5]", into = "[f64; 5]")]
pub struct StripePoint {
    pub u: f64,
    pub v: f64,
    pub intensity: f64,
    pub width: f64,
    pub quality: u32,
}

/// Quality flags of a stripe point.
pub mod quality {
    /// Part of the profile was saturated; the centre is the plateau's centre.
    pub const SATURATED: u32 = 1;
    /// Low peak-to-threshold contrast.
    pub const WEAK: u32 = 2;
    /// Width near the accepted bounds.
    pub const WIDTH_MARGINAL: u32 = 4;
}

/// A whole number ≥ 0 carried as a JSON or binary array's f64 (`field` names it).
fn whole(value: f64, field: &str) -> std::result::Result<u32, String> {
    if value.fract() == 0.0 && (0.0..=f64::from(u32::MAX)).contains(&value) {
        Ok(value as u32)
    } else {
        Err(format!("{field} must be a whole number from 0 to {}, got {}", u32::MAX, omni_model::limits::shown(value)))
    }
}

impl TryFrom<[f64; 5]> for StripePoint {
    type Error = String;
    fn try_from(a: [f64; 5]) -> std::result::Result<Self, String> {
        Ok(StripePoint { u: a[0], v: a[1], intensity: a[2], width: a[3], quality: whole(a[4], "quality")? })
    }
}
impl From<StripePoint> for [f64; 5] {
    fn from(p: StripePoint) -> Self {
        [p.u, p.v, p.intensity, p.width, p.quality as f64]
    }
}

/// A triangulated point: serialised as `[x, y, z, laser, range, stripe_index]` (mm, world
/// frame; range = distance from the viewpoint; stripe_index indexes the frame's `stripe`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(try_from = "[f64; 6]", into = "[f64; 6]")]
pub struct Point {
    pub xyz: [f64; 3],
    pub laser: u32,
    pub range: f64,
    pub stripe_index: u32,
}

impl TryFrom<[f64; 6]> for Point {
    type Error = String;
    fn try_from(a: [f64; 6]) -> std::result::Result<Self, String> {
        let (laser, stripe_index) = (whole(a[3], "laser")?, whole(a[5], "stripe_index")?);
        Ok(Point { xyz: [a[0], a[1], a[2]], laser, range: a[4], stripe_index })
    }
}
impl From<Point> for [f64; 6] {
    fn from(p: Point) -> Self {
        [p.xyz[0], p.xyz[1], p.xyz[2], p.laser as f64, p.range, p.stripe_index as f64]
    }
}

/// One frame of the scan, growing along the pipe. Read by [`FrameVisitor`]: a derived reader
/// with `extra` flattened would first copy every field, the stripe's and points' arrays too,
/// into an untyped buffer.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Frame {
    /// Frame sequence number (0-based, increasing; gaps mean lost frames).
    pub seq: u64,
    /// Image file (PNG 8/16-bit); relative paths are resolved against the header's `frames_dir`.
    pub path: String,
    /// Mirror angle within the facet (degrees).
    pub alpha_deg: f64,
    /// Facet facing laser 0.
    pub facet: u32,
    /// Polygon revolution counter.
    #[serde(default)]
    pub revolution: u64,
    /// Raw encoder count, if known.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub encoder: Option<u64>,
    /// Controller timestamp of the trigger (µs).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub timestamp_us: Option<u64>,
    /// Lasers that were on (empty = a laser-off/ambient frame).
    #[serde(default = "all_lasers")]
    pub lasers: Vec<u32>,
    /// A laser-off frame of the same view for ambient subtraction.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ambient_path: Option<String>,
    /// Stripe centres (added by omni-ridge).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub stripe: Option<Vec<StripePoint>>,
    /// 3D points (added by omni-triangulate).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub points: Option<Vec<Point>>,
    /// Any other fields, passed through untouched.
    #[serde(flatten)]
    pub extra: serde_json::Map<String, serde_json::Value>,
}

fn all_lasers() -> Vec<u32> {
    vec![0, 1]
}

impl<'de> Deserialize<'de> for Frame {
    fn deserialize<D: serde::Deserializer<'de>>(deserializer: D) -> std::result::Result<Self, D::Error> {
        deserializer.deserialize_map(FrameVisitor)
    }
}

/// Reads a frame's fields straight into their types, the others into [`Frame::extra`]; the same
/// defaults and refusals (a missing or repeated field) as a derived reader.
struct FrameVisitor;

impl<'de> serde::de::Visitor<'de> for FrameVisitor {
    type Value = Frame;

    fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
        f.write_str("a frame record")
    }

    fn visit_map<A: serde::de::MapAccess<'de>>(self, mut map: A) -> std::result::Result<Frame, A::Error> {
        use serde::de::Error as _;
        let (mut seq, mut path, mut alpha_deg, mut facet, mut revolution) = (None, None, None, None, None);
        let (mut encoder, mut timestamp_us, mut lasers, mut ambient_path) = (None, None, None, None);
        let (mut stripe, mut points, mut extra) = (None, None, serde_json::Map::new());
        /// Reads the field's value into its slot, refusing a second one.
        fn once<'de, A: serde::de::MapAccess<'de>, T: Deserialize<'de>>(
            map: &mut A,
            slot: &mut Option<T>,
            name: &'static str,
        ) -> std::result::Result<(), A::Error> {
            if slot.is_some() {
                return Err(A::Error::duplicate_field(name));
            }
            *slot = Some(map.next_value()?);
            Ok(())
        }
        while let Some(key) = map.next_key::<std::borrow::Cow<'de, str>>()? {
            match key.as_ref() {
                "seq" => once(&mut map, &mut seq, "seq")?,
                "path" => once(&mut map, &mut path, "path")?,
                "alpha_deg" => once(&mut map, &mut alpha_deg, "alpha_deg")?,
                "facet" => once(&mut map, &mut facet, "facet")?,
                "revolution" => once(&mut map, &mut revolution, "revolution")?,
                "encoder" => once(&mut map, &mut encoder, "encoder")?,
                "timestamp_us" => once(&mut map, &mut timestamp_us, "timestamp_us")?,
                "lasers" => once(&mut map, &mut lasers, "lasers")?,
                "ambient_path" => once(&mut map, &mut ambient_path, "ambient_path")?,
                "stripe" => once(&mut map, &mut stripe, "stripe")?,
                "points" => once(&mut map, &mut points, "points")?,
                _ => {
                    extra.insert(key.into_owned(), map.next_value()?);
                }
            }
        }
        Ok(Frame {
            seq: seq.ok_or_else(|| A::Error::missing_field("seq"))?,
            path: path.ok_or_else(|| A::Error::missing_field("path"))?,
            alpha_deg: alpha_deg.ok_or_else(|| A::Error::missing_field("alpha_deg"))?,
            facet: facet.ok_or_else(|| A::Error::missing_field("facet"))?,
            revolution: revolution.unwrap_or_default(),
            encoder: encoder.flatten(),
            timestamp_us: timestamp_us.flatten(),
            lasers: lasers.unwrap_or_else(all_lasers),
            ambient_path: ambient_path.flatten(),
            stripe: stripe.flatten(),
            points: points.flatten(),
            extra,
        })
    }
}

/// A frame record whose tag comes first, as every omniscan tool writes it: read on from the tag
/// by [`FrameVisitor`], where the tagged [`Record`]'s reader would first copy every field, the
/// arrays too, into an untyped buffer to find its tag. Any other record is refused, for
/// [`Record`]'s reader to take.
struct FrameTaggedFirst(Frame);

impl<'de> Deserialize<'de> for FrameTaggedFirst {
    fn deserialize<D: serde::Deserializer<'de>>(deserializer: D) -> std::result::Result<Self, D::Error> {
        deserializer.deserialize_map(TaggedFirstVisitor)
    }
}

struct TaggedFirstVisitor;

impl<'de> serde::de::Visitor<'de> for TaggedFirstVisitor {
    type Value = FrameTaggedFirst;

    fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
        f.write_str("a frame record, its tag first")
    }

    fn visit_map<A: serde::de::MapAccess<'de>>(self, mut map: A) -> std::result::Result<FrameTaggedFirst, A::Error> {
        use serde::de::Error as _;
        let tagged = map.next_key::<std::borrow::Cow<'de, str>>()?.is_some_and(|k| k == "type")
            && map.next_value::<std::borrow::Cow<'de, str>>()? == "frame";
        if !tagged {
            return Err(A::Error::custom("not a frame tagged first"));
        }
        let frame = FrameVisitor.visit_map(map)?;
        if frame.extra.contains_key("type") {
            return Err(A::Error::duplicate_field("type"));
        }
        Ok(FrameTaggedFirst(frame))
    }
}

/// An image path of a frame record: relative paths are relative to the header's `frames_dir`.
pub fn resolve_frame_path(frames_dir: Option<&str>, path: &str) -> std::path::PathBuf {
    let p = std::path::Path::new(path);
    match frames_dir {
        Some(d) if p.is_relative() => std::path::Path::new(d).join(p),
        _ => p.to_path_buf(),
    }
}

impl Frame {
    /// A frame record with no stripe or points yet.
    pub fn new(seq: u64, path: impl Into<String>, alpha_deg: f64, facet: u32) -> Self {
        Frame {
            seq,
            path: path.into(),
            alpha_deg,
            facet,
            revolution: 0,
            encoder: None,
            timestamp_us: None,
            lasers: all_lasers(),
            ambient_path: None,
            stripe: None,
            points: None,
            extra: Default::default(),
        }
    }

    /// Checks numbers are finite; the message names the field.
    pub fn validate(&self) -> std::result::Result<(), String> {
        if !self.alpha_deg.is_finite() {
            return Err("field alpha_deg: not a finite number".into());
        }
        if let Some(s) = &self.stripe {
            for (i, p) in s.iter().enumerate() {
                if !(p.u.is_finite() && p.v.is_finite() && p.intensity.is_finite() && p.width.is_finite()) {
                    return Err(format!("field stripe[{i}]: not a finite number"));
                }
            }
        }
        if let Some(pts) = &self.points {
            for (i, p) in pts.iter().enumerate() {
                if !(p.xyz.iter().all(|x| x.is_finite()) && p.range.is_finite()) {
                    return Err(format!("field points[{i}]: not a finite number"));
                }
                let max = omni_model::limits::MAX_COORDINATE_MM;
                if let Some(x) = p.xyz.iter().chain([&p.range]).find(|x| x.abs() > max) {
                    return Err(format!(
                        "field points[{i}]: {} mm is beyond ±{max:e} mm",
                        omni_model::limits::shown(*x)
                    ));
                }
            }
        }
        Ok(())
    }

    /// The frame's image path resolved against the stream's frames directory.
    pub fn resolve_path(&self, frames_dir: Option<&str>, path: &str) -> std::path::PathBuf {
        resolve_frame_path(frames_dir, path)
    }
}

/// Last record: whether the stream is complete and what was lost.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Status {
    /// Frame records written.
    pub frames: u64,
    /// Frames known to be missing (lost triggers or frames).
    #[serde(default)]
    pub frames_missing: u64,
    /// Frames that failed and were skipped (with `--keep-going`).
    #[serde(default)]
    pub frames_failed: u64,
    /// Whether the producer finished normally.
    pub complete: bool,
    /// Human-readable problems, one per entry.
    #[serde(default)]
    pub errors: Vec<String>,
    #[serde(flatten)]
    pub extra: serde_json::Map<String, serde_json::Value>,
}

impl Status {
    /// The status of a stream of `frames` frames that ended normally: nothing missing or failed.
    pub fn complete(frames: u64) -> Self {
        Status { complete: true, errors: vec![], ..Status::cut_short(frames, "") }
    }

    /// The status a tool passes on for an input that was cut short (no status record):
    /// `complete: false`, with the reason.
    pub fn cut_short(frames: u64, message: impl Into<String>) -> Self {
        Status {
            frames,
            frames_missing: 0,
            frames_failed: 0,
            complete: false,
            errors: vec![message.into()],
            extra: Default::default(),
        }
    }
}

/// A per-frame error record.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FrameError {
    pub seq: u64,
    #[serde(default)]
    pub path: String,
    pub message: String,
}

/// Serde loses field paths inside flattened structs; re-check the typed array fields one by one
/// so the message names e.g. `stripe[3]`.
fn locate_frame_error(v: &serde_json::Value) -> Option<String> {
    fn probe<T: serde::de::DeserializeOwned>(v: &serde_json::Value, key: &str) -> Option<String> {
        let field = v.get(key)?;
        serde_path_to_error::deserialize::<_, T>(field.clone())
            .err()
            .map(|e| format!("field {key}{}: {}", e.path().to_string().trim_start_matches('.'), e.inner()))
    }
    if v.get("type")?.as_str()? != "frame" {
        return None;
    }
    probe::<Vec<StripePoint>>(v, "stripe")
        .or_else(|| probe::<Vec<Point>>(v, "points"))
        .or_else(|| probe::<Vec<u32>>(v, "lasers"))
}

/// Reads records line by line; errors name the source and the line.
pub struct StreamReader<R> {
    reader: R,
    name: String,
    line_no: usize,
    buf: String,
    saw_header: bool,
    /// Whether any non-blank line was read: an input without one is refused once.
    saw_line: bool,
    saw_status: bool,
    at_end: bool,
    base_dir: Option<std::path::PathBuf>,
    /// The header said version 2: frames may carry binary arrays.
    binary_allowed: bool,
}

/// A header's `frames_dir` as [`StreamReader::with_base_dir`] resolves it against `base` (the
/// stream file's directory): `base/frames_dir` unless it is absolute, `base` is `.`, or only the
/// current directory has it.
pub fn resolve_frames_dir(base: &std::path::Path, frames_dir: &str) -> String {
    let rel = std::path::Path::new(frames_dir);
    if rel.is_absolute() || base == std::path::Path::new(".") {
        return frames_dir.to_string();
    }
    let joined = base.join(rel);
    if joined.is_dir() || !rel.is_dir() { joined.display().to_string() } else { frames_dir.to_string() }
}

/// The `frames_dir` a manifest written to `manifest` (`-` = stdout) records for the frames
/// directory `frames` (as given, relative to the current directory): relative to the manifest's
/// own directory, which is what readers resolve it against ([`resolve_frames_dir`]), so that the
/// manifest reads back from anywhere and moves with its frames. Stdout and a manifest in the
/// current directory keep the path as given.
pub fn frames_dir_for_manifest(manifest: &std::path::Path, frames: &std::path::Path) -> String {
    let base = manifest.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(std::path::Path::new("."));
    if manifest == std::path::Path::new("-") || base == std::path::Path::new(".") || frames.is_absolute() {
        return frames.display().to_string();
    }
    let (Ok(from), Ok(to)) = (std::path::absolute(base), std::path::absolute(frames)) else {
        return frames.display().to_string();
    };
    let (from, to): (Vec<_>, Vec<_>) = (from.components().collect(), to.components().collect());
    let common = from.iter().zip(&to).take_while(|(a, b)| a == b).count();
    let mut rel = std::path::PathBuf::new();
    for _ in common..from.len() {
        rel.push("..");
    }
    to[common..].iter().for_each(|c| rel.push(c));
    if rel.as_os_str().is_empty() { ".".to_string() } else { rel.display().to_string() }
}

impl StreamReader<Box<dyn BufRead + Send>> {
    /// Opens a stream file (`-` = stdin). A header's relative `frames_dir` is resolved against
    /// the file's own directory (see [`StreamReader::with_base_dir`]); from stdin, against the
    /// current directory.
    pub fn open(path: &std::path::Path) -> Result<Self> {
        let name = crate::io::display_name(path, "stdin");
        if path == std::path::Path::new("-") {
            let stdin: Box<dyn BufRead + Send> = Box::new(std::io::BufReader::with_capacity(1 << 16, std::io::stdin()));
            return Ok(StreamReader::new(stdin, name));
        }
        let f = std::fs::File::open(path).map_err(|e| Error::io(&name, &e))?;
        let file: Box<dyn BufRead + Send> = Box::new(std::io::BufReader::with_capacity(1 << 16, f));
        let dir = path.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(std::path::Path::new("."));
        Ok(StreamReader::new(file, name).with_base_dir(dir))
    }
}

/// Why an input without a single record is refused: a pipe whose upstream tool failed gives
/// one, and passing it on as an empty scan would hide that failure.
pub const EMPTY_STREAM: &str = "empty stream (no header, no frames: did the tool before this one fail?)";

impl<R: BufRead> StreamReader<R> {
    pub fn new(reader: R, name: impl Into<String>) -> Self {
        StreamReader {
            reader,
            name: name.into(),
            line_no: 0,
            buf: String::new(),
            saw_header: false,
            saw_line: false,
            saw_status: false,
            at_end: false,
            base_dir: None,
            binary_allowed: false,
        }
    }

    /// Resolves a header's relative `frames_dir` against `dir`, the directory of the stream's
    /// file, so a manifest read from elsewhere still finds its frames: the header record comes
    /// out with `dir/frames_dir`. A manifest written by an older tool, whose `frames_dir` is
    /// relative to the current directory, keeps it if only that directory exists.
    pub fn with_base_dir(mut self, dir: &std::path::Path) -> Self {
        self.base_dir = Some(dir.to_path_buf());
        self
    }

    fn resolve_frames_dir(&self, header: &mut Header) {
        let (Some(base), Some(d)) = (&self.base_dir, &header.frames_dir) else { return };
        header.frames_dir = Some(resolve_frames_dir(base, d));
    }

    /// Whether the stream has ended without its final `status` record: it was cut short
    /// upstream (docs/FORMATS.md). False until the end has been read.
    pub fn cut_short(&self) -> bool {
        self.at_end && !self.saw_status
    }

    /// The one-line explanation of a [`cut_short`](Self::cut_short) stream, naming it.
    pub fn cut_short_message(&self) -> String {
        format!("{}: the stream ends without its status record (cut short upstream?)", self.name)
    }

    /// The line number of the last record read (1-based).
    pub fn line(&self) -> usize {
        self.line_no
    }

    pub fn name(&self) -> &str {
        &self.name
    }

    /// The next record, `Ok(None)` at the end; an input without any record is refused
    /// ([`EMPTY_STREAM`]). Blank lines are skipped. A header with another
    /// format or an unknown version is refused, and so is a stream out of order: one header
    /// first, then frames (and `--keep-going`'s error records), then at most one status.
    pub fn next_record(&mut self) -> Result<Option<Record>> {
        loop {
            self.buf.clear();
            let n = self.reader.read_line(&mut self.buf).map_err(|e| Error::io(&self.name, &e))?;
            if n == 0 {
                let first_time = !self.at_end;
                self.at_end = true;
                if first_time && !self.saw_line {
                    // Nothing at all: most often the tool before this one in the pipe failed.
                    return Err(Error::new(&self.name, "", EMPTY_STREAM));
                }
                return Ok(None);
            }
            self.line_no += 1;
            let line = self.buf.trim();
            if line.is_empty() {
                continue;
            }
            self.saw_line = true;
            let loc = format!("line {}", self.line_no);
            // Straight into the record: the common case, without a JSON tree in between.
            let parsed = serde_json::from_str::<FrameTaggedFirst>(line).map(|f| Record::Frame(Box::new(f.0)));
            let mut record = match parsed.or_else(|_| serde_json::from_str::<Record>(line)).ok() {
                Some(Record::Header(_)) | None => Self::parse_checked(line, &self.name, &loc)
                    .map_err(|e| if self.saw_header { e } else { not_a_stream(e, line) })?,
                Some(record) => record,
            };
            self.check_order(&record).map_err(|m| Error::new(&self.name, &loc, m))?;
            match &mut record {
                Record::Header(h) => self.binary_allowed = h.version >= STREAM_BINARY_VERSION,
                Record::Frame(f) => {
                    let at = format!("{loc} (frame {})", f.seq);
                    if self.binary_allowed && f.extra.contains_key(BINARY_FIELD) {
                        self.read_binary_arrays(f).map_err(|m| Error::new(&self.name, &at, m))?;
                    }
                    f.validate().map_err(|m| Error::new(&self.name, &at, m))?;
                }
                Record::Status(_) => self.saw_status = true,
                _ => {}
            }
            if let Record::Header(h) = &mut record {
                self.resolve_frames_dir(h);
            }
            return Ok(Some(record));
        }
    }
}

impl<R: BufRead> StreamReader<R> {
    /// Checks that `record` may come next: the header first and once, nothing after the status.
    fn check_order(&mut self, record: &Record) -> std::result::Result<(), String> {
        let kind = match record {
            Record::Header(_) => "header",
            Record::Frame(_) => "frame",
            Record::Status(_) => "status",
            Record::Error(_) => "error",
        };
        if self.saw_status {
            return Err(format!("a {kind} record after the stream's status record (its last)"));
        }
        match (record, self.saw_header) {
            (Record::Header(_), true) => Err("a second header record".into()),
            (Record::Header(_), false) => {
                self.saw_header = true;
                Ok(())
            }
            (_, false) => Err(format!("the stream starts with a {kind} record, not its header")),
            (_, true) => Ok(()),
        }
    }

    /// Reads the arrays a binary frame announces (`"binary": {"stripe": N, "points": M}`, either
    /// key absent when the array is): N stripe points of 5 and M points of 6 little-endian f64,
    /// right after the record's line.
    fn read_binary_arrays(&mut self, f: &mut Frame) -> std::result::Result<(), String> {
        let spec = f.extra.remove(BINARY_FIELD).unwrap_or_default();
        let count = |key: &str| -> std::result::Result<Option<usize>, String> {
            match spec.get(key) {
                None => Ok(None),
                Some(v) => v
                    .as_u64()
                    .and_then(|n| usize::try_from(n).ok())
                    .filter(|&n| n <= MAX_BINARY_POINTS)
                    .map(Some)
                    .ok_or_else(|| format!("field binary.{key}: not a point count (0..={MAX_BINARY_POINTS})")),
            }
        };
        let (stripe, points) = (count("stripe")?, count("points")?);
        if let Some(n) = stripe {
            let v = self.read_f64s::<5>(n).map_err(|e| format!("binary stripe ({n} points): {e}"))?;
            let stripe = v
                .into_iter()
                .enumerate()
                .map(|(i, a)| StripePoint::try_from(a).map_err(|e| format!("binary stripe[{i}]: {e}")));
            f.stripe = Some(stripe.collect::<std::result::Result<_, _>>()?);
        }
        if let Some(n) = points {
            let v = self.read_f64s::<6>(n).map_err(|e| format!("binary points ({n} points): {e}"))?;
            let points = v
                .into_iter()
                .enumerate()
                .map(|(i, a)| Point::try_from(a).map_err(|e| format!("binary points[{i}]: {e}")));
            f.points = Some(points.collect::<std::result::Result<_, _>>()?);
        }
        Ok(())
    }

    fn read_f64s<const K: usize>(&mut self, n: usize) -> std::io::Result<Vec<[f64; K]>> {
        let mut bytes = vec![0u8; n * K * 8];
        self.reader.read_exact(&mut bytes)?;
        Ok(bytes
            .chunks_exact(K * 8)
            .map(|c| std::array::from_fn(|i| f64::from_le_bytes(c[8 * i..8 * i + 8].try_into().expect("8 bytes"))))
            .collect())
    }
}

/// More points than any frame holds: a count past it is a corrupt record, not an allocation.
const MAX_BINARY_POINTS: usize = 1 << 24;

impl<R> StreamReader<R> {
    /// The slow path, for headers (format and version checked first) and for records that do
    /// not parse (the error names the field at fault).
    fn parse_checked(line: &str, name: &str, loc: &str) -> Result<Record> {
        let value: serde_json::Value =
            serde_json::from_str(line).map_err(|e| Error::new(name, loc, format!("invalid JSON: {e}")))?;
        if value.get("type").and_then(|t| t.as_str()) == Some("header") {
            crate::docs::check_header_versions(&value, STREAM_FORMAT, STREAM_VERSION, STREAM_BINARY_VERSION, name)
                .map_err(|e| Error::new(name, format!("{loc}, {}", e.location), e.message))?;
        }
        let probe = value.clone();
        serde_path_to_error::deserialize(value).map_err(|e| {
            let path = e.path().to_string();
            let loc = if path == "." { loc.to_string() } else { format!("{loc}, field {path}") };
            match locate_frame_error(&probe) {
                Some(field_err) => Error::new(name, &loc, field_err),
                None => Error::new(name, loc, e.into_inner().to_string()),
            }
        })
    }
}

/// The error of a first line that is no stream record, saying what the input is instead
/// where it can tell: another omniscan file (its `format`), or a JSON document spread over lines.
fn not_a_stream(mut e: Error, first_line: &str) -> Error {
    let format = serde_json::from_str::<serde_json::Value>(first_line)
        .ok()
        .and_then(|v| v.get("format").and_then(|f| f.as_str()).map(str::to_string));
    let what = match format {
        Some(f) if f != STREAM_FORMAT => format!("an {f} file"),
        _ if first_line == "{" || first_line == "[" => "a JSON document over several lines".to_string(),
        _ => return e,
    };
    e.message = format!("{what}, not an omniscan stream (JSON Lines starting with a header record); {}", e.message);
    e
}

impl<R: BufRead> Iterator for StreamReader<R> {
    type Item = Result<Record>;
    fn next(&mut self) -> Option<Self::Item> {
        self.next_record().transpose()
    }
}

/// Writes records, one per line, flushing after each so a pipe downstream starts at once.
pub struct StreamWriter<W: Write> {
    writer: W,
    name: String,
    /// Flush after every record (for live pipes); off for bulk files.
    pub flush_each: bool,
    /// Frames' stripe and point arrays in binary after their line (stream version 2).
    binary: bool,
}

impl<W: Write> StreamWriter<W> {
    pub fn new(writer: W, name: impl Into<String>) -> Self {
        StreamWriter { writer, name: name.into(), flush_each: true, binary: false }
    }

    /// Writes each frame's `stripe` and `points` as little-endian f64 arrays after its line
    /// instead of JSON numbers (the header says version 2): the same values, bit for bit, at a
    /// fraction of the cost of printing and parsing them. Every reader of this crate reads both.
    pub fn binary(mut self, on: bool) -> Self {
        self.binary = on;
        self
    }

    pub fn write(&mut self, record: &Record) -> Result<()> {
        match record {
            // The version says how this writer writes, whatever the stream read was: a
            // version 1 reader reads a JSON-only stream.
            Record::Header(h) => {
                let mut h = h.clone();
                h.version = if self.binary { STREAM_BINARY_VERSION } else { STREAM_VERSION };
                self.write_line(&Record::Header(h))?;
            }
            Record::Frame(f) if self.binary && (f.stripe.is_some() || f.points.is_some()) => {
                self.write_binary_frame(f)?
            }
            _ => self.write_line(record)?,
        }
        if self.flush_each {
            self.writer.flush().map_err(|e| Error::io(&self.name, &e))?;
        }
        Ok(())
    }

    fn write_line(&mut self, record: &Record) -> Result<()> {
        serde_json::to_writer(&mut self.writer, record).map_err(|e| Error::new(&self.name, "", e.to_string()))?;
        self.writer.write_all(b"\n").map_err(|e| Error::io(&self.name, &e))
    }

    fn write_binary_frame(&mut self, f: &Frame) -> Result<()> {
        // The record without its arrays (cloning them only to drop them would cost a copy).
        let mut head = Frame {
            seq: f.seq,
            path: f.path.clone(),
            alpha_deg: f.alpha_deg,
            facet: f.facet,
            revolution: f.revolution,
            encoder: f.encoder,
            timestamp_us: f.timestamp_us,
            lasers: f.lasers.clone(),
            ambient_path: f.ambient_path.clone(),
            stripe: None,
            points: None,
            extra: f.extra.clone(),
        };
        let mut spec = serde_json::Map::new();
        if let Some(s) = &f.stripe {
            spec.insert("stripe".into(), s.len().into());
        }
        if let Some(p) = &f.points {
            spec.insert("points".into(), p.len().into());
        }
        head.extra.insert(BINARY_FIELD.into(), spec.into());
        self.write_line(&Record::Frame(Box::new(head)))?;
        let mut bytes = Vec::with_capacity(
            f.stripe.as_ref().map_or(0, |s| s.len() * 40) + f.points.as_ref().map_or(0, |p| p.len() * 48),
        );
        for s in f.stripe.iter().flatten() {
            <[f64; 5]>::from(*s).iter().for_each(|x| bytes.extend_from_slice(&x.to_le_bytes()));
        }
        for p in f.points.iter().flatten() {
            <[f64; 6]>::from(*p).iter().for_each(|x| bytes.extend_from_slice(&x.to_le_bytes()));
        }
        self.writer.write_all(&bytes).map_err(|e| Error::io(&self.name, &e))
    }

    pub fn flush(&mut self) -> Result<()> {
        self.writer.flush().map_err(|e| Error::io(&self.name, &e))
    }

    pub fn into_inner(self) -> W {
        self.writer
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn records_round_trip_and_keep_unknown_fields() {
        let mut f = Frame::new(3, "f.png", 12.5, 4);
        f.stripe = Some(vec![StripePoint { u: 1.5, v: 2.25, intensity: 200.0, width: 3.0, quality: 0 }]);
        f.extra.insert("exposure_us".into(), 500.into());
        let recs =
            vec![Record::Header(Header::new("test")), Record::Frame(Box::new(f)), Record::Status(Status::complete(1))];
        let mut w = StreamWriter::new(Vec::new(), "mem");
        for r in &recs {
            w.write(r).unwrap();
        }
        let text = String::from_utf8(w.into_inner()).unwrap();
        assert!(text.contains("\"stripe\":[[1.5,2.25,200.0,3.0,0.0]]"), "{text}");
        assert!(text.contains("\"exposure_us\":500"));
        let back: Vec<Record> = StreamReader::new(text.as_bytes(), "mem").map(|r| r.unwrap()).collect();
        assert_eq!(back, recs);
    }

    /// A frame line with its tag first (as omniscan writes it) and the same frame with its tag
    /// elsewhere read alike, defaults, nulls and unknown fields included; a second tag or a
    /// field of the wrong type is refused.
    #[test]
    fn frames_read_alike_wherever_their_tag_stands() {
        let header = "{\"type\":\"header\",\"format\":\"omniscan.stream\",\"version\":1}\n";
        let fields = r#""seq":7,"path":"a.png","alpha_deg":1.5,"facet":2,"encoder":null,"stripe":[[1,2,3,4,1]],"gain":[1,{"x":null}]"#;
        let read = |line: String| {
            let text = format!("{header}{line}\n");
            StreamReader::new(text.as_bytes(), "s").nth(1).unwrap()
        };
        let first = read(format!(r#"  {{"type":"frame",{fields}}}"#)).unwrap();
        let later = read(format!(r#"{{{fields},"type":"frame"}}"#)).unwrap();
        assert_eq!(first, later);
        let Record::Frame(f) = first else { panic!("{first:?}") };
        assert_eq!((f.seq, f.revolution, f.encoder, f.lasers.as_slice()), (7, 0, None, [0, 1].as_slice()));
        assert_eq!(f.stripe.unwrap()[0].quality, 1);
        assert_eq!(f.extra["gain"], serde_json::json!([1, {"x": null}]));
        for bad in [
            r#"{"type":"frame","type":"status","seq":1,"path":"a.png","alpha_deg":1,"facet":0}"#,
            r#"{"type":"frame","seq":1,"path":"a.png","alpha_deg":1,"facet":0,"stripe":[[1,2,3,4,0.5]]}"#,
            r#"{"type":"frame","seq":-1,"path":"a.png","alpha_deg":1,"facet":0}"#,
        ] {
            let e = read(bad.into()).unwrap_err().to_string();
            assert!(e.contains("s: line 2"), "{bad}: {e}");
        }
    }

    #[test]
    fn bad_lines_are_named() {
        let text = "{\"type\":\"header\",\"format\":\"omniscan.stream\",\"version\":9}\n";
        let e = StreamReader::new(text.as_bytes(), "s.jsonl").next().unwrap().unwrap_err().to_string();
        assert!(e.contains("s.jsonl: line 1") && e.contains("unsupported version 9"), "{e}");
        let text = "\n{\"type\":\"frame\",\"seq\":1,\"path\":\"a.png\",\"facet\":0}\n";
        let e = StreamReader::new(text.as_bytes(), "s.jsonl").next().unwrap().unwrap_err().to_string();
        assert!(e.contains("line 2") && e.contains("alpha_deg"), "{e}");
        let text = "{\"type\":\"frame\",\"seq\":1,\"path\":\"a.png\",\"alpha_deg\":1,\"facet\":0,\"stripe\":[[1,2]]}\n";
        let e = StreamReader::new(text.as_bytes(), "s.jsonl").next().unwrap().unwrap_err().to_string();
        assert!(e.contains("stripe"), "{e}");
        let text =
            "{\"type\":\"frame\",\"seq\":1,\"path\":\"a.png\",\"alpha_deg\":1,\"facet\":0,\"stripe\":[[1,2,3,4,0]]\n";
        let e = StreamReader::new(text.as_bytes(), "s.jsonl").next().unwrap().unwrap_err().to_string();
        assert!(e.contains("invalid JSON"), "{e}");
    }

    #[test]
    fn an_empty_input_or_another_file_is_refused_saying_what_it_is() {
        let first = |text: &str| StreamReader::new(text.as_bytes(), "in").next().unwrap().unwrap_err().to_string();
        assert!(first("").contains("in: empty stream"), "{}", first(""));
        assert!(first("\n\n").contains("in: empty stream"), "{}", first("\n\n"));
        // Refused once: a reader asked again is at the end.
        let mut empty = StreamReader::new("".as_bytes(), "in");
        assert!(empty.next_record().is_err() && empty.next_record().unwrap().is_none());
        let camera = first("{\n  \"format\": \"omniscan.camera\"\n}\n");
        assert!(camera.contains("line 1: a JSON document over several lines, not an omniscan stream"), "{camera}");
        let truth = first("{\"format\":\"omniscan.sim-truth\",\"version\":1}\n");
        assert!(truth.contains("an omniscan.sim-truth file, not an omniscan stream"), "{truth}");
        // A frame before the header is a stream out of order, said as such.
        let headless = first("{\"type\":\"frame\",\"seq\":1,\"path\":\"a.png\",\"alpha_deg\":1,\"facet\":0}\n");
        assert!(headless.contains("starts with a frame record"), "{headless}");
    }

    #[test]
    fn a_manifest_records_its_frames_relative_to_itself() {
        use std::path::Path;
        assert_eq!(frames_dir_for_manifest(Path::new("scan.jsonl"), Path::new("fr")), "fr");
        assert_eq!(frames_dir_for_manifest(Path::new("-"), Path::new("fr")), "fr");
        assert_eq!(frames_dir_for_manifest(Path::new("sub/scan.jsonl"), Path::new("fr")), "../fr");
        assert_eq!(frames_dir_for_manifest(Path::new("sub/scan.jsonl"), Path::new("sub/fr")), "fr");
        assert_eq!(frames_dir_for_manifest(Path::new("a/b/s.jsonl"), Path::new("a/c/fr")), "../c/fr");
        assert_eq!(frames_dir_for_manifest(Path::new("sub/s.jsonl"), Path::new("/abs/fr")), "/abs/fr");
        assert_eq!(frames_dir_for_manifest(Path::new("sub/s.jsonl"), Path::new("sub")), ".");
        // What a reader of sub/scan.jsonl makes of it: the frames where they are.
        let back =
            resolve_frames_dir(Path::new("sub"), &frames_dir_for_manifest(Path::new("sub/s.jsonl"), Path::new("fr")));
        assert_eq!(Path::new(&back), Path::new("sub/../fr"));
    }

    #[test]
    fn a_stream_without_status_is_cut_short() {
        let header = "{\"type\":\"header\",\"format\":\"omniscan.stream\",\"version\":1,\"producers\":[\"t\"]}\n";
        let status = "{\"type\":\"status\",\"frames\":0,\"complete\":true}\n";
        let mut r = StreamReader::new(header.as_bytes(), "cut.jsonl");
        while r.next_record().unwrap().is_some() {
            assert!(!r.cut_short(), "not before the end");
        }
        assert!(r.cut_short());
        assert!(r.cut_short_message().starts_with("cut.jsonl: "));
        let whole = format!("{header}{status}");
        let mut r = StreamReader::new(whole.as_bytes(), "whole.jsonl");
        while r.next_record().unwrap().is_some() {}
        assert!(!r.cut_short());
    }

    #[test]
    fn frames_dir_resolves_against_the_manifest_directory() {
        let dir = tempfile::tempdir().unwrap();
        let scan = dir.path().join("scan");
        std::fs::create_dir_all(scan.join("frames")).unwrap();
        let manifest = scan.join("m.jsonl");
        let header = |d: &str| {
            format!("{{\"type\":\"header\",\"format\":\"omniscan.stream\",\"version\":1,\"frames_dir\":\"{d}\"}}\n")
        };
        let first = |path: &std::path::Path| match StreamReader::open(path).unwrap().next_record().unwrap() {
            Some(Record::Header(h)) => h.frames_dir.unwrap(),
            other => panic!("{other:?}"),
        };
        std::fs::write(&manifest, header("frames")).unwrap();
        assert_eq!(first(&manifest), scan.join("frames").display().to_string());
        // Absolute paths stay; a missing directory is named as tried next to the manifest.
        let abs = scan.join("frames").display().to_string();
        std::fs::write(&manifest, header(&abs)).unwrap();
        assert_eq!(first(&manifest), abs);
        std::fs::write(&manifest, header("nowhere")).unwrap();
        assert_eq!(first(&manifest), scan.join("nowhere").display().to_string());
        // Without a base directory (stdin, StreamReader::new) nothing changes.
        let text = header("frames");
        let Some(Record::Header(h)) = StreamReader::new(text.as_bytes(), "stdin").next_record().unwrap() else {
            panic!()
        };
        assert_eq!(h.frames_dir.as_deref(), Some("frames"));
    }

    fn measured_frame(seq: u64) -> Frame {
        let mut f = Frame::new(seq, format!("{seq}.png"), 0.1 + seq as f64, 2);
        f.extra.insert("exposure_us".into(), 500.into());
        f.stripe = Some(
            (0..7)
                .map(|i| StripePoint { u: 0.1 * i as f64, v: 1.0 / 3.0, intensity: 1e-300, width: 2.5, quality: 5 })
                .collect(),
        );
        f.points =
            Some(vec![Point { xyz: [1.0 / 7.0, -2.5, 1e8 + 1.0 / 3.0], laser: 1, range: 3.25, stripe_index: 6 }]);
        f
    }

    fn binary_stream(frames: &[Frame]) -> Vec<u8> {
        let mut w = StreamWriter::new(Vec::new(), "mem").binary(true);
        w.write(&Record::Header(Header::new("test"))).unwrap();
        for f in frames {
            w.write(&Record::Frame(Box::new(f.clone()))).unwrap();
        }
        w.write(&Record::Status(Status::complete(frames.len() as u64))).unwrap();
        w.into_inner()
    }

    /// A stream is one header, then frames and error records, then at most one status: a
    /// stream out of that order is refused at the line that breaks it.
    #[test]
    fn records_out_of_order_are_named() {
        let header = "{\"type\":\"header\",\"format\":\"omniscan.stream\",\"version\":1}\n";
        let frame = "{\"type\":\"frame\",\"seq\":0,\"path\":\"a\",\"alpha_deg\":0,\"facet\":0}\n";
        let status = "{\"type\":\"status\",\"frames\":1,\"complete\":true}\n";
        let cases = [
            (frame.to_string(), "line 1: the stream starts with a frame record, not its header"),
            (status.to_string(), "line 1: the stream starts with a status record"),
            (format!("{header}{frame}{header}"), "line 3: a second header record"),
            (format!("{header}{status}{frame}"), "line 3: a frame record after the stream's status record"),
            (format!("{header}{frame}{status}{status}"), "line 4: a status record after"),
        ];
        for (text, expected) in cases {
            let err = StreamReader::new(text.as_bytes(), "s").collect::<Result<Vec<_>>>().unwrap_err().to_string();
            assert!(err.contains(expected), "{text:?}: {err}");
        }
        let fine = format!("{header}{frame}{frame}{status}");
        assert_eq!(StreamReader::new(fine.as_bytes(), "s").collect::<Result<Vec<_>>>().unwrap().len(), 4);
    }

    /// A point's whole-number fields must be whole numbers ≥ 0 and its coordinates within
    /// ±1e9 mm, in JSON and in the binary arrays alike: a reader never rounds -1 or 0.5 to 0.
    #[test]
    fn points_with_wrong_indices_or_coordinates_beyond_reach_are_named() {
        let frame = |points: &str| {
            "{\"type\":\"header\",\"format\":\"omniscan.stream\",\"version\":1}\n".to_string()
                + &format!(
                    "{{\"type\":\"frame\",\"seq\":0,\"path\":\"a\",\"alpha_deg\":0,\"facet\":0,\"points\":[{points}]}}\n"
                )
        };
        let cases = [
            ("[1,2,3,-1,4,0]", "points[0]: laser must be a whole number"),
            ("[1,2,3,0,4,0.5]", "points[0]: stripe_index must be a whole number"),
            ("[1,2,3e300,0,4,0]", "points[0]: 3e300 mm is beyond"),
        ];
        for (points, expected) in cases {
            let text = frame(points);
            let err =
                StreamReader::new(text.as_bytes(), "p.jsonl").collect::<Result<Vec<_>>>().unwrap_err().to_string();
            assert!(err.contains("p.jsonl: line 2") && err.contains(expected), "{points}: {err}");
        }
        let mut f = measured_frame(0);
        f.points.as_mut().unwrap()[0].xyz[0] = -2e9;
        let bytes = binary_stream(&[f]);
        let err = StreamReader::new(std::io::Cursor::new(&bytes), "b").collect::<Result<Vec<_>>>().unwrap_err();
        assert!(err.to_string().contains("points[0]: -2e9 mm is beyond"), "{err}");
    }

    #[test]
    fn binary_arrays_read_back_bit_for_bit_beside_json_records() {
        let mut empty = measured_frame(2);
        empty.stripe = Some(vec![]);
        empty.points = None;
        let frames = [measured_frame(0), Frame::new(1, "1.png", 0.0, 0), empty, measured_frame(3)];
        let bytes = binary_stream(&frames);
        let records: Vec<Record> =
            StreamReader::new(std::io::Cursor::new(&bytes), "mem").collect::<Result<_>>().unwrap();
        let Record::Header(h) = &records[0] else { panic!() };
        assert_eq!(h.version, STREAM_BINARY_VERSION);
        for (r, f) in records[1..5].iter().zip(&frames) {
            assert_eq!(r, &Record::Frame(Box::new(f.clone())));
        }
        assert!(matches!(records[5], Record::Status(_)));
        // Written again as JSON, the stream is version 1 again: every reader reads it.
        let mut w = StreamWriter::new(Vec::new(), "mem");
        records.iter().try_for_each(|r| w.write(r)).unwrap();
        let text = String::from_utf8(w.into_inner()).unwrap();
        assert!(text.starts_with("{\"type\":\"header\",\"format\":\"omniscan.stream\",\"version\":1"), "{text}");
        assert_eq!(StreamReader::new(text.as_bytes(), "json").collect::<Result<Vec<_>>>().unwrap()[1..], records[1..]);
    }

    #[test]
    fn a_cut_or_corrupt_binary_frame_is_named_and_a_version_1_stream_ignores_the_field() {
        let bytes = binary_stream(&[measured_frame(0), measured_frame(1)]);
        let cut = &bytes[..bytes.len() - 200];
        let err = StreamReader::new(std::io::Cursor::new(cut), "cut.jsonl")
            .collect::<Result<Vec<_>>>()
            .unwrap_err()
            .to_string();
        assert!(err.contains("cut.jsonl") && err.contains("frame 1") && err.contains("binary"), "{err}");
        let text = String::from_utf8_lossy(&bytes).replace("\"points\":1", "\"points\":-1");
        let err = StreamReader::new(std::io::Cursor::new(text.as_bytes()), "bad.jsonl")
            .collect::<Result<Vec<_>>>()
            .unwrap_err()
            .to_string();
        assert!(err.contains("binary.points"), "{err}");
        // Without version 2 a `binary` field is any unknown field: passed through.
        let v1 = "{\"type\":\"header\",\"format\":\"omniscan.stream\",\"version\":1}\n\
                  {\"type\":\"frame\",\"seq\":0,\"path\":\"a\",\"alpha_deg\":0,\"facet\":0,\"binary\":{\"points\":3}}\n";
        let recs: Vec<Record> = StreamReader::new(std::io::Cursor::new(v1), "v1").collect::<Result<_>>().unwrap();
        let Record::Frame(f) = &recs[1] else { panic!() };
        assert!(f.points.is_none() && f.extra.contains_key("binary"));
    }
}
