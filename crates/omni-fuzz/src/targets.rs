//! The fuzz targets: each feeds bytes to one real reader, through its public API.
//!
//! A target returns `Ok(())` or the reader's clean error message. Where a reader's `Ok` makes a
//! promise (finite coordinates, a record the writer can write and the reader read back, a model
//! that can be used), the target checks it with an assertion, so a broken promise is a crash.

use nalgebra::{Point3, Vector2};
use omni_formats::stream::{Record, StreamReader};
use omni_formats::{BoardFile, CameraFile, ScannerFile, scene::SceneFile};
use omni_hw::controller::{Controller, ControllerSpec};
use omni_hw::framing::{LineReader, decode_line};
use omni_hw::message::{DeviceMessage, Request};

/// A reader under test.
pub struct Target {
    /// Name on the command line and prefix of its seed and regression files.
    pub name: &'static str,
    /// What it feeds the bytes to.
    pub about: &'static str,
    /// Runs one input: `Ok` or a clean error; a panic is a bug.
    pub run: fn(&[u8]) -> Result<(), String>,
}

/// Every target, in the order `--target all` runs them.
pub const TARGETS: &[Target] = &[
    Target { name: "ply", about: "omni_formats::ply::read_ply_from", run: ply },
    Target { name: "stream", about: "omni_formats::stream::StreamReader (JSON Lines records)", run: stream },
    Target { name: "camera", about: "CameraFile::parse (camera.json) and the model it builds", run: camera },
    Target { name: "scanner", about: "ScannerFile::parse (scanner.json) and the transmitter", run: scanner },
    Target { name: "board", about: "parse_doc::<BoardFile> (board.json)", run: board },
    Target { name: "scene", about: "parse_doc::<SceneFile> (the simulator's scene.json)", run: scene },
    Target { name: "controller", about: "omni_hw framing, message parsers and controller logic", run: controller },
];

/// The target called `name`.
pub fn find(name: &str) -> Option<&'static Target> {
    TARGETS.iter().find(|t| t.name == name)
}

/// PLY: a cloud that reads must have finite coordinates and one scalar value per point.
fn ply(data: &[u8]) -> Result<(), String> {
    let cloud = omni_formats::ply::read_ply_from(&mut &data[..], "fuzz.ply").map_err(|e| e.to_string())?;
    assert!(cloud.positions.iter().flatten().all(|c| c.is_finite()), "read_ply_from accepted a non-finite point");
    for s in &cloud.scalars {
        assert_eq!(s.values.len(), cloud.positions.len(), "scalar field {} has the wrong length", s.name);
    }
    Ok(())
}

/// Stream: every record is read (a bad line does not end the stream, so the reader's recovery is
/// fuzzed too), each accepted record must survive the writer and be read back identically, and
/// the reader must advance on every call.
fn stream(data: &[u8]) -> Result<(), String> {
    let mut reader = StreamReader::new(data, "fuzz.jsonl");
    let mut first_error = None;
    for _ in 0..=data.len() + 1 {
        match reader.next_record() {
            Ok(Some(record)) => check_record_round_trip(&record),
            Ok(None) => return first_error.map_or(Ok(()), Err),
            Err(e) => {
                first_error.get_or_insert(e.to_string());
            }
        }
    }
    panic!("StreamReader returned more records than the input has bytes (not advancing)")
}

/// What the writer makes of an accepted record must read back as the same record, every float
/// to the bit: the workspace builds serde_json with `float_roundtrip`, so a number keeps its
/// value through any number of tools in a pipe.
fn check_record_round_trip(record: &Record) {
    let line = serde_json::to_string(record).expect("an accepted record must serialise");
    // A stream starts with its header: any other record is read back after one.
    let is_header = matches!(record, Record::Header(_));
    let header = serde_json::to_string(&Record::Header(omni_formats::stream::Header::new("omni-fuzz")))
        .expect("a header serialises");
    let text = if is_header { line.clone() } else { format!("{header}\n{line}\n") };
    let mut back = StreamReader::new(text.as_bytes(), "round-trip");
    if !is_header {
        back.next_record().expect("the header reads back");
    }
    match back.next_record() {
        Ok(Some(again)) => {
            let (a, b) = (serde_json::to_value(record), serde_json::to_value(&again));
            let (Ok(a), Ok(b)) = (a, b) else { panic!("a record read back does not serialise: {line}") };
            assert!(json_close(&a, &b), "record changed through write + read: {line} became {b}");
        }
        other => panic!("an accepted record does not read back: {other:?} from {line}"),
    }
}

/// Whether two JSON values are equal, floats compared as f64 (an integer-valued float may come
/// back as an integer).
fn json_close(a: &serde_json::Value, b: &serde_json::Value) -> bool {
    use serde_json::Value;
    match (a, b) {
        (Value::Number(x), Value::Number(y)) if x.is_f64() || y.is_f64() => {
            let (x, y) = (x.as_f64().unwrap_or(f64::NAN), y.as_f64().unwrap_or(f64::NAN));
            x == y
        }
        (Value::Array(x), Value::Array(y)) => x.len() == y.len() && x.iter().zip(y).all(|(x, y)| json_close(x, y)),
        (Value::Object(x), Value::Object(y)) => {
            x.len() == y.len() && x.iter().all(|(k, v)| y.get(k).is_some_and(|w| json_close(v, w)))
        }
        _ => a == b,
    }
}

/// camera.json: a model that loads must answer the questions the tools ask of it.
fn camera(data: &[u8]) -> Result<(), String> {
    let (_, model) = CameraFile::parse(data, "camera.json").map_err(|e| e.to_string())?;
    let (w, h) = model.image_size();
    let _ = model.mirror_circle();
    let (w, h) = (f64::from(w), f64::from(h));
    for (u, v) in [(0.0, 0.0), (w / 2.0, h / 2.0), (w - 1.0, h - 1.0), (w / 3.0, h * 0.7)] {
        let px = Vector2::new(u, v);
        let _ = model.in_image(&px);
        if let Some(ray) = model.pixel_to_ray(&px) {
            let _ = model.point_to_pixel(&(ray.origin + ray.dir.into_inner() * 1000.0));
        }
    }
    for p in [Point3::new(1000.0, 0.0, 0.0), Point3::new(0.0, -500.0, 200.0), Point3::origin()] {
        let _ = model.point_to_pixel(&p);
    }
    Ok(())
}

/// scanner.json: a transmitter that loads must give light planes for valid frames.
fn scanner(data: &[u8]) -> Result<(), String> {
    let (_, model) = ScannerFile::parse(data, "scanner.json").map_err(|e| e.to_string())?;
    let tx = match model {
        omni_model::TransmitterModel::Polygon(tx) => tx,
        omni_model::TransmitterModel::FixedPlanes(f) => {
            for laser in f.lasers() {
                let _ = f.plane(laser);
            }
            return Ok(());
        }
    };
    let _ = tx.split_angle(123.456);
    for facet in 0..tx.num_facets().min(4) {
        for alpha in [0.0, tx.facet_angle() / 3.0] {
            if tx.check_frame(alpha, facet).is_ok() {
                for laser in 0..tx.num_lasers() {
                    let _ = tx.light_plane(alpha, facet, laser);
                }
            }
        }
    }
    Ok(())
}

/// board.json (with its size limits).
fn board(data: &[u8]) -> Result<(), String> {
    omni_formats::parse_doc::<BoardFile>(data, "board.json").map(drop).map_err(|e| e.to_string())
}

/// The simulator's scene.json (with its shape checks).
fn scene(data: &[u8]) -> Result<(), String> {
    omni_formats::parse_doc::<SceneFile>(data, "scene.json").map(drop).map_err(|e| e.to_string())
}

/// The controller protocol, both ways: the framed byte stream through [`LineReader`], and every
/// line (CRC checked or not, so mutations reach the message parsers) through both message
/// parsers and a controller's command handling, with its clock advancing.
fn controller(data: &[u8]) -> Result<(), String> {
    let mut bodies = Vec::new();
    let mut reader = LineReader::new();
    for chunk in data.chunks(7) {
        reader.push(chunk, &mut bodies);
    }
    let mut device = Controller::new(ControllerSpec::default());
    let mut now_us = 0u64;
    let mut first_error = None;
    for line in data.split(|&b| b == b'\n').filter(|l| !l.is_empty() && *l != b"\r") {
        if let Err(e) = decode_line(line) {
            first_error.get_or_insert(format!("line: {e}"));
        }
        let Ok(body) = std::str::from_utf8(star_body(line)) else { continue };
        let (device_message, request) = (DeviceMessage::parse(body), Request::parse(body));
        if let (Err(d), Err(r)) = (&device_message, &request) {
            first_error.get_or_insert(format!("neither a controller message ({d}) nor a command ({r})"));
        }
        let _ = device.handle_line(body, now_us);
        now_us += 20_000;
        let _ = device.poll(now_us);
    }
    first_error.map_or(Ok(()), Err)
}

/// The body of a protocol line: the part before its last `*` (the checksum), if any.
fn star_body(line: &[u8]) -> &[u8] {
    let line = line.strip_suffix(b"\r").unwrap_or(line);
    line.iter().rposition(|&b| b == b'*').map_or(line, |star| &line[..star])
}
