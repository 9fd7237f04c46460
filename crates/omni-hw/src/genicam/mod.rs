//! GenICam cameras (GigE Vision, USB3 Vision) driven through Aravis: listing, setup, and a
//! [`FrameSource`](crate::pairing::FrameSource) that writes every frame the camera delivers and
//! names the trigger it answers.
//!
//! This module holds what needs no camera library, so it is tested without one: the
//! `aravis:ID` spec, the settings and their checks against what a camera offers, and the
//! bookkeeping ([`FrameBook`]) that turns the stream's buffers into numbered, timestamped frames.
//! The camera itself (`open`, `list_devices`, `AravisFrameSource`) needs feature `aravis` (the
//! system `libaravis-0.8`).
//!
//! Frames are numbered by the camera's frame id ([`BlockIdUnwrapper`]: GigE Vision's 16-bit
//! block id wraps), so frames lost on the way are counted exactly. Timestamps are the camera's
//! exposure timestamps mapped onto the host clock ([`CameraClock`]: the smallest "arrival −
//! stamp" difference seen, like the controller clock in [`crate::pairing`]). With the software
//! trigger the host fires the camera for each controller trigger event and records which trigger
//! each firing was for ([`TriggerLedger`]); each frame then names its trigger, and the pairing
//! still checks the timestamp. With a hardware line the pairing goes by timestamp alone.

#[cfg(feature = "aravis")]
mod device;
#[cfg(feature = "aravis")]
pub use device::{AravisFrameSource, list_devices, open};

use crate::frame_id::{BlockIdUnwrapper, LossCount, TriggerLedger};
use crate::frame_writer::FrameFormat;
use crate::pairing::CapturedFrame;
use std::path::PathBuf;

/// The device id in a `--camera` spec: `aravis:DEVICE_ID` (Aravis is the only camera library
/// omniscan drives; the id may itself contain colons, e.g. an IPv6 address).
pub fn parse_camera_spec(spec: &str) -> Result<&str, String> {
    match spec.split_once(':') {
        Some(("aravis", id)) if !id.trim().is_empty() => Ok(id),
        _ => Err(format!("{spec:?}: expected aravis:DEVICE_ID (the only camera library omniscan drives)")),
    }
}

/// A GenICam device found on the host's interfaces.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct DeviceEntry {
    /// The id to pass as `aravis:ID`.
    pub id: String,
    pub vendor: String,
    pub model: String,
    pub serial: String,
    /// `GigEVision`, `USB3Vision` or `Fake`.
    pub interface: String,
    /// Network address (GigE) or bus address.
    pub address: String,
}

/// Pixel formats a frame can be captured in.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Pixel {
    Mono8,
    Mono16,
}

impl Pixel {
    /// Parses the GenICam name (`Mono8`, `Mono16`; case-insensitive).
    pub fn parse(s: &str) -> Result<Self, String> {
        match s.to_ascii_lowercase().as_str() {
            "mono8" => Ok(Pixel::Mono8),
            "mono16" => Ok(Pixel::Mono16),
            _ => Err(format!("unsupported pixel format {s:?} (omniscan captures Mono8 or Mono16)")),
        }
    }

    /// The GenICam `PixelFormat` entry name.
    pub fn name(self) -> &'static str {
        match self {
            Pixel::Mono8 => "Mono8",
            Pixel::Mono16 => "Mono16",
        }
    }

    /// Bits per sample.
    pub fn bit_depth(self) -> u8 {
        match self {
            Pixel::Mono8 => 8,
            Pixel::Mono16 => 16,
        }
    }
}

/// What starts an exposure.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Trigger {
    /// The host executes `TriggerSoftware` for every controller trigger event (tests, rigs
    /// without a trigger wire).
    Software,
    /// A hardware input line wired to the controller's trigger output (`Line0`, ...), rising
    /// edge.
    Line(String),
}

impl Trigger {
    /// `software` or a line name such as `Line0`.
    pub fn parse(s: &str) -> Result<Self, String> {
        if s.eq_ignore_ascii_case("software") {
            Ok(Trigger::Software)
        } else if !s.is_empty() && s.chars().all(|c| c.is_ascii_alphanumeric() || c == '_') {
            Ok(Trigger::Line(s.to_string()))
        } else {
            Err(format!("bad trigger {s:?}: `software` or a line name such as Line0"))
        }
    }

    /// The GenICam `TriggerSource` entry.
    pub fn source(&self) -> &str {
        match self {
            Trigger::Software => "Software",
            Trigger::Line(l) => l,
        }
    }
}

/// A region of interest on the sensor (px).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Roi {
    pub x: u32,
    pub y: u32,
    pub width: u32,
    pub height: u32,
}

impl Roi {
    /// Parses `X,Y,WIDTH,HEIGHT` (px).
    pub fn parse(s: &str) -> Result<Self, String> {
        let v: Vec<u32> = s
            .split(',')
            .map(|w| w.trim().parse::<u32>())
            .collect::<Result<_, _>>()
            .map_err(|_| format!("bad ROI {s:?}: expected X,Y,WIDTH,HEIGHT in pixels"))?;
        match v[..] {
            [x, y, width, height] if width > 0 && height > 0 => Ok(Roi { x, y, width, height }),
            _ => Err(format!("bad ROI {s:?}: expected X,Y,WIDTH,HEIGHT in pixels, width and height > 0")),
        }
    }

    /// (x, y, width, height) as GenICam's integer features take them (saturated at `i32::MAX`,
    /// which no sensor reaches: [`check_roi`] refuses it first).
    pub fn region(self) -> (i32, i32, i32, i32) {
        let c = |v: u32| i32::try_from(v).unwrap_or(i32::MAX);
        (c(self.x), c(self.y), c(self.width), c(self.height))
    }

    fn text(self) -> String {
        format!("{},{},{},{}", self.x, self.y, self.width, self.height)
    }
}

/// The pixel format is among those the camera offers (its `PixelFormat` entries).
pub fn check_pixel_format(label: &str, pixel: Pixel, offered: &[&str]) -> Result<(), String> {
    if offered.contains(&pixel.name()) {
        return Ok(());
    }
    Err(format!("{label}: the camera does not offer pixel format {} (it offers: {})", pixel.name(), offered.join(", ")))
}

/// The ROI lies inside a sensor of `sensor` = (width, height) px.
pub fn check_roi(label: &str, roi: Roi, sensor: (i32, i32)) -> Result<(), String> {
    let (sw, sh) = sensor;
    let inside = |o: u32, len: u32, side: i32| o as u64 + len as u64 <= side.max(0) as u64;
    if inside(roi.x, roi.width, sw) && inside(roi.y, roi.height, sh) {
        Ok(())
    } else {
        Err(format!("{label}: ROI {} lies outside the {sw}x{sh} px sensor", roi.text()))
    }
}

/// The camera took the ROI as asked (cameras round offsets and sizes to their increments).
pub fn check_roi_taken(label: &str, roi: Roi, got: (i32, i32, i32, i32)) -> Result<(), String> {
    if got == roi.region() {
        return Ok(());
    }
    Err(format!(
        "{label}: the camera set the ROI to {},{},{},{} instead of {} (check its size increments)",
        got.0,
        got.1,
        got.2,
        got.3,
        roi.text()
    ))
}

/// `value` lies within the camera's range `bounds` (inclusive), e.g. the exposure in µs.
pub fn check_in_range(label: &str, what: &str, value: f64, unit: &str, bounds: (f64, f64)) -> Result<(), String> {
    let (lo, hi) = bounds;
    if (lo..=hi).contains(&value) {
        Ok(())
    } else {
        Err(format!("{label}: {what} {value} {unit} outside the camera's range {lo}..{hi} {unit}"))
    }
}

/// The trigger source is among the camera's `TriggerSource` entries (none: the camera has no
/// trigger mode, so it cannot be synchronised with the controller).
pub fn check_trigger_source(label: &str, trigger: &Trigger, offered: &[&str]) -> Result<(), String> {
    if offered.contains(&trigger.source()) {
        return Ok(());
    }
    Err(format!(
        "{label}: the camera refuses trigger source {} (it offers: {})",
        trigger.source(),
        if offered.is_empty() { "none: no trigger mode".to_string() } else { offered.join(", ") }
    ))
}

/// How to set the camera up.
#[derive(Debug, Clone, PartialEq)]
pub struct CameraSettings {
    pub pixel: Pixel,
    /// Exposure time (µs); `None` keeps the camera's.
    pub exposure_us: Option<f64>,
    /// Analog gain (dB); `None` keeps the camera's.
    pub gain_db: Option<f64>,
    /// `None` keeps the camera's region.
    pub roi: Option<Roi>,
    pub trigger: Trigger,
    /// Stream buffers (each one frame's payload): the memory the stream may hold.
    pub buffers: usize,
    pub frame_format: FrameFormat,
    /// Threads encoding and writing frames.
    pub writer_threads: usize,
    /// Sync each frame file to disk before it is handed on (see [`crate::frame_writer`]).
    pub sync_frames: bool,
}

impl Default for CameraSettings {
    fn default() -> Self {
        CameraSettings {
            pixel: Pixel::Mono8,
            exposure_us: None,
            gain_db: None,
            roi: None,
            trigger: Trigger::Software,
            buffers: 16,
            frame_format: FrameFormat::Pgm,
            writer_threads: 2,
            sync_frames: false,
        }
    }
}

/// Camera timestamps onto the host clock: camera stamp + the smallest "arrival − stamp"
/// difference seen (the transfer's fixed part; any later frame that took longer on the wire
/// would otherwise look exposed later than it was).
#[derive(Debug, Clone, Default)]
pub struct CameraClock {
    /// Host clock − camera clock (ns), the smallest seen.
    offset_ns: Option<i128>,
}

impl CameraClock {
    /// The exposure's host-clock time (µs) of a frame stamped `camera_ns` by the camera that
    /// arrived at host time `arrival_ns`; the arrival time if the camera does not stamp (0).
    pub fn host_time_us(&mut self, camera_ns: u64, arrival_ns: u64) -> i64 {
        if camera_ns == 0 {
            return (arrival_ns / 1000) as i64;
        }
        let offset = arrival_ns as i128 - camera_ns as i128;
        let best = self.offset_ns.map_or(offset, |o| o.min(offset));
        self.offset_ns = Some(best);
        ((camera_ns as i128 + best) / 1000) as i64
    }
}

/// What became of a buffer's transfer.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum BufferState {
    /// Every packet arrived and the image is whole.
    Complete,
    /// The transfer succeeded but the image is not what the pixel format says (the reason).
    Unusable(String),
    /// The stream's failure status (Aravis's `BufferStatus`, e.g. `MissingPackets`, `Timeout`).
    Broken(String),
}

/// A buffer the stream handed back, reduced to what the bookkeeping needs.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct BufferMeta {
    /// The camera's frame id (GigE Vision: the 16-bit block id; 0 when none of the leader
    /// arrived).
    pub block_id: u64,
    pub state: BufferState,
    /// The camera's exposure timestamp (ns, camera clock; 0 if it does not stamp).
    pub camera_ns: u64,
    /// Host time the buffer arrived (ns since the Unix epoch).
    pub arrival_ns: u64,
}

/// The bookkeeping of one acquisition: numbers each buffer by its unwrapped frame id, names the
/// trigger a frame answers (software trigger), counts and describes broken and lost frames for
/// the manifest, and maps timestamps onto the host clock.
#[derive(Debug, Clone)]
pub struct FrameBook {
    label: String,
    format: FrameFormat,
    ids: BlockIdUnwrapper,
    /// Software trigger mode: the triggers fired, to name each frame's trigger.
    ledger: Option<TriggerLedger>,
    clock: CameraClock,
    losses: Vec<String>,
    received: u64,
    broken: LossCount,
    software_triggers: u64,
}

impl FrameBook {
    /// The book of camera `label` (for messages) triggered by `trigger`, whose frames are named
    /// `NNNNNN.<format's extension>` after their frame index.
    pub fn new(label: &str, trigger: &Trigger, format: FrameFormat) -> Self {
        FrameBook {
            label: label.to_string(),
            format,
            ids: BlockIdUnwrapper::default(),
            ledger: (*trigger == Trigger::Software).then(TriggerLedger::default),
            clock: CameraClock::default(),
            losses: Vec::new(),
            received: 0,
            broken: LossCount::default(),
            software_triggers: 0,
        }
    }

    /// Controller trigger `seq` arrived at host time `now_us`: with the software trigger it is
    /// recorded and the caller must fire the camera (true); with a hardware line, nothing to do.
    pub fn fire(&mut self, seq: u64, now_us: i64) -> bool {
        let Some(ledger) = self.ledger.as_mut() else { return false };
        ledger.record(seq, now_us);
        self.software_triggers += 1;
        true
    }

    /// Books one buffer: the frame to write (its `name`, host time, trigger and camera fields
    /// set; `path` left for the writer), or `None` for a broken, unusable or stale buffer, which
    /// is counted and described instead.
    pub fn arrive(&mut self, b: &BufferMeta) -> Option<CapturedFrame> {
        let raw = b.block_id;
        // Id 0 is reserved: an incomplete buffer carries it when none of its leader arrived.
        let unnamed = raw == 0 && b.state != BufferState::Complete;
        let index = if unnamed { None } else { self.ids.push(raw) };
        if let Some((index, skipped)) = index
            && skipped > 0
        {
            self.broken.skipped(index - skipped..index);
            self.losses.push(format!("{}: {skipped} camera frame(s) before block id {raw} never arrived", self.label));
        }
        let index = index.map(|(index, _)| index);
        match (&b.state, index) {
            (BufferState::Complete, Some(index)) => {
                self.received += 1;
                Some(self.frame(b, index))
            }
            (BufferState::Unusable(why), Some(index)) => {
                self.received += 1;
                self.broken.incomplete_named(index);
                self.losses.push(format!("{}: camera frame block id {raw}: {why}", self.label));
                None
            }
            (BufferState::Complete | BufferState::Unusable(_), None) => {
                self.losses.push(format!("{}: camera frame with stale block id {raw} dropped", self.label));
                None
            }
            (BufferState::Broken(status), index) => {
                match index {
                    Some(index) => self.broken.incomplete_named(index),
                    None if unnamed => self.broken.incomplete_unnamed(),
                    None => self.broken.incomplete_late(self.ids.index_of(raw)),
                }
                self.losses.push(format!("{}: camera frame block id {raw} incomplete ({status})", self.label));
                None
            }
        }
    }

    fn frame(&mut self, b: &BufferMeta, index: u64) -> CapturedFrame {
        let time_us = self.clock.host_time_us(b.camera_ns, b.arrival_ns);
        let mut frame = CapturedFrame::new(PathBuf::new(), self.format.file_name(&format!("{index:06}")), time_us);
        frame.trigger_seq = self.ledger.as_mut().and_then(|l| l.answer(time_us));
        frame.extra.insert("camera_frame".into(), index.into());
        frame.extra.insert("camera_block_id".into(), b.block_id.into());
        frame.extra.insert("camera_timestamp_ns".into(), b.camera_ns.into());
        frame
    }

    /// The loss descriptions since the previous call, one line each.
    pub fn take_losses(&mut self) -> Vec<String> {
        std::mem::take(&mut self.losses)
    }

    /// The status record's camera counters: frames received, incomplete (lost packets or an
    /// unusable image), lost (never arrived), software triggers sent.
    pub fn counters(&self) -> serde_json::Map<String, serde_json::Value> {
        let mut m = serde_json::Map::new();
        m.insert("camera_frames_received".into(), self.received.into());
        m.insert("camera_frames_incomplete".into(), self.broken.incomplete.into());
        m.insert("camera_frames_lost".into(), self.broken.lost.into());
        m.insert("camera_software_triggers".into(), self.software_triggers.into());
        m
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const LABEL: &str = "aravis:cam";

    #[test]
    fn camera_specs_name_aravis_and_a_device() {
        assert_eq!(parse_camera_spec("aravis:192.168.1.20"), Ok("192.168.1.20"));
        assert_eq!(parse_camera_spec("aravis:Basler-21234567"), Ok("Basler-21234567"));
        assert_eq!(parse_camera_spec("aravis:fe80::1"), Ok("fe80::1"), "the id keeps its own colons");
        for bad in ["aravis:", "aravis: ", "basler:1", "Aravis-Fake-GV01", "", ":x"] {
            let e = parse_camera_spec(bad).unwrap_err();
            assert!(e.contains("expected aravis:DEVICE_ID"), "{bad:?}: {e}");
        }
    }

    #[test]
    fn pixel_formats_trigger_sources_and_rois_parse() {
        assert_eq!(Pixel::parse("mono16").map(Pixel::bit_depth), Ok(16));
        assert_eq!(Pixel::parse("Mono8").map(Pixel::name), Ok("Mono8"));
        assert!(Pixel::parse("RGB8").unwrap_err().contains("Mono8 or Mono16"));
        assert!(Pixel::parse("Mono12").is_err(), "12-bit packed is not written");
        assert_eq!(Trigger::parse("SOFTWARE"), Ok(Trigger::Software));
        assert_eq!(Trigger::parse("Line0").unwrap().source(), "Line0");
        assert_eq!(Trigger::Software.source(), "Software");
        for bad in ["", "Line 0", "Line0;rm", "-1"] {
            assert!(Trigger::parse(bad).unwrap_err().contains("bad trigger"), "{bad:?}");
        }
        assert_eq!(Roi::parse(" 8, 16,1024 ,512"), Ok(Roi { x: 8, y: 16, width: 1024, height: 512 }));
        for bad in ["0,0,0,5", "0,0,5", "0,0,5,5,5", "-1,0,4,4", "a,b,c,d", "0,0,4,4.5"] {
            assert!(Roi::parse(bad).unwrap_err().starts_with("bad ROI"), "{bad:?}");
        }
        let huge = Roi { x: 0, y: 0, width: u32::MAX, height: 1 };
        assert_eq!(huge.region(), (0, 0, i32::MAX, 1));
    }

    #[test]
    fn settings_are_checked_against_what_the_camera_offers() {
        let offered = ["Mono8", "Mono16", "RGB8Packed"];
        assert_eq!(check_pixel_format(LABEL, Pixel::Mono16, &offered), Ok(()));
        assert_eq!(
            check_pixel_format(LABEL, Pixel::Mono16, &["Mono8", "BayerRG8"]).unwrap_err(),
            "aravis:cam: the camera does not offer pixel format Mono16 (it offers: Mono8, BayerRG8)"
        );
        // The fake camera's 2048 x 2048 sensor: the last row and column are inside.
        let roi = |s| Roi::parse(s).unwrap();
        assert_eq!(check_roi(LABEL, roi("1024,1024,1024,1024"), (2048, 2048)), Ok(()));
        assert_eq!(
            check_roi(LABEL, roi("1025,0,1024,64"), (2048, 2048)).unwrap_err(),
            "aravis:cam: ROI 1025,0,1024,64 lies outside the 2048x2048 px sensor"
        );
        assert!(check_roi(LABEL, roi("0,1,64,2048"), (2048, 2048)).is_err());
        assert!(check_roi(LABEL, Roi { x: u32::MAX, y: 0, width: u32::MAX, height: 1 }, (2048, 2048)).is_err());
        assert!(check_roi(LABEL, roi("0,0,1,1"), (-1, 0)).is_err(), "a camera reporting no sensor");
        assert_eq!(check_roi_taken(LABEL, roi("0,0,64,48"), (0, 0, 64, 48)), Ok(()));
        assert_eq!(
            check_roi_taken(LABEL, roi("3,0,66,48"), (0, 0, 64, 48)).unwrap_err(),
            "aravis:cam: the camera set the ROI to 0,0,64,48 instead of 3,0,66,48 (check its size increments)"
        );
        // Bounds are inclusive; NaN is never inside.
        assert_eq!(check_in_range(LABEL, "exposure", 10.0, "µs", (10.0, 1e6)), Ok(()));
        assert_eq!(check_in_range(LABEL, "exposure", 1e6, "µs", (10.0, 1e6)), Ok(()));
        assert_eq!(
            check_in_range(LABEL, "gain", 12.5, "dB", (0.0, 10.0)).unwrap_err(),
            "aravis:cam: gain 12.5 dB outside the camera's range 0..10 dB"
        );
        assert!(check_in_range(LABEL, "exposure", f64::NAN, "µs", (0.0, 1e6)).is_err());
        assert_eq!(check_trigger_source(LABEL, &Trigger::Line("Line0".into()), &["Line0", "Software"]), Ok(()));
        assert_eq!(
            check_trigger_source(LABEL, &Trigger::Line("Line7".into()), &["Line0", "Software"]).unwrap_err(),
            "aravis:cam: the camera refuses trigger source Line7 (it offers: Line0, Software)"
        );
        assert!(
            check_trigger_source(LABEL, &Trigger::Software, &[])
                .unwrap_err()
                .ends_with("(it offers: none: no trigger mode)")
        );
    }

    /// Host clock 1000 s ahead of the camera's; transfers take 3, 1 and 2 ms.
    #[test]
    fn camera_stamps_move_onto_the_host_clock_by_the_quickest_transfer() {
        const AHEAD_NS: u64 = 1_000_000_000_000;
        let mut c = CameraClock::default();
        assert_eq!(c.host_time_us(2_000_000, 2_000_000 + AHEAD_NS + 3_000_000), 1_000_005_000);
        assert_eq!(c.host_time_us(12_000_000, 12_000_000 + AHEAD_NS + 1_000_000), 1_000_013_000);
        // A slower transfer later does not move the frame later: the 1 ms offset stays.
        assert_eq!(c.host_time_us(22_000_000, 22_000_000 + AHEAD_NS + 2_000_000), 1_000_023_000);
        assert_eq!(c.host_time_us(0, 5_000_000_123), 5_000_000, "no camera stamp: the arrival");
    }

    fn buffer(block_id: u64, state: BufferState, camera_ms: u64) -> BufferMeta {
        // Host clock = camera clock + 1 s, 1 ms transfer.
        let camera_ns = camera_ms * 1_000_000;
        BufferMeta { block_id, state, camera_ns, arrival_ns: camera_ns + 1_001_000_000 }
    }

    fn counters(book: &FrameBook) -> [u64; 4] {
        let m = book.counters();
        ["camera_frames_received", "camera_frames_incomplete", "camera_frames_lost", "camera_software_triggers"]
            .map(|k| m[k].as_u64().unwrap())
    }

    /// Triggers fired by software at host times 1.010, 1.060, 1.110 s; the camera answers the
    /// first and third (the second's frame was lost), across the block id wrap.
    #[test]
    fn software_triggered_frames_name_their_trigger_and_camera_fields() {
        let mut book = FrameBook::new(LABEL, &Trigger::Software, FrameFormat::Pgm);
        assert!(book.fire(40, 1_010_000));
        let f = book.arrive(&buffer(65535, BufferState::Complete, 12)).unwrap();
        assert_eq!((f.name.as_str(), f.time_us, f.trigger_seq), ("000000.pgm", 1_013_000, Some(40)));
        assert_eq!(f.extra["camera_frame"], 0);
        assert_eq!(f.extra["camera_block_id"], 65535);
        assert_eq!(f.extra["camera_timestamp_ns"], 12_000_000);
        assert!(book.fire(41, 1_060_000));
        assert!(book.fire(42, 1_110_000));
        // Block id 1 (trigger 41's) never came: 65535 is followed by 2 two frames on.
        let f = book.arrive(&buffer(2, BufferState::Complete, 112)).unwrap();
        assert_eq!((f.name.as_str(), f.trigger_seq), ("000002.pgm", Some(42)), "not trigger 41");
        assert_eq!(book.take_losses(), ["aravis:cam: 1 camera frame(s) before block id 2 never arrived"]);
        assert_eq!(counters(&book), [2, 0, 1, 3]);
        // A frame no trigger was fired before answers none.
        assert_eq!(book.arrive(&buffer(3, BufferState::Complete, 200)).unwrap().trigger_seq, None);
    }

    #[test]
    fn a_hardware_line_fires_nothing_and_names_no_trigger() {
        let mut book = FrameBook::new(LABEL, &Trigger::Line("Line0".into()), FrameFormat::Png);
        assert!(!book.fire(0, 1_000_000), "the controller's line fires the camera");
        let f = book.arrive(&buffer(65400, BufferState::Complete, 5)).unwrap();
        assert_eq!((f.name.as_str(), f.trigger_seq, f.time_us), ("000000.png", None, 1_006_000));
        assert_eq!(counters(&book), [1, 0, 0, 0]);
    }

    /// Every kind of broken buffer is counted once, in the manifest's counters, and described.
    #[test]
    fn broken_buffers_map_onto_the_manifest_counters() {
        let mut book = FrameBook::new(LABEL, &Trigger::Software, FrameFormat::Pgm);
        let broken = |s: &str| BufferState::Broken(s.to_string());
        assert!(book.arrive(&buffer(65534, BufferState::Complete, 0)).is_some());
        assert!(book.arrive(&buffer(65535, broken("MissingPackets"), 10)).is_none());
        assert_eq!(counters(&book), [1, 1, 0, 0]);
        // Block id 1 skipped: lost until an incomplete buffer without an id accounts for it.
        assert_eq!(book.arrive(&buffer(2, BufferState::Complete, 30)).unwrap().name, "000003.pgm");
        assert_eq!(counters(&book), [2, 1, 1, 0]);
        assert!(book.arrive(&buffer(0, broken("Timeout"), 0)).is_none());
        assert_eq!(counters(&book), [2, 2, 0, 0]);
        // A whole copy of a frame already booked is stale; a partial one of it is no new loss.
        assert!(book.arrive(&buffer(65535, BufferState::Complete, 10)).is_none());
        assert!(book.arrive(&buffer(2, broken("MissingPackets"), 30)).is_none());
        assert_eq!(counters(&book), [2, 2, 0, 0]);
        assert!(
            book.arrive(&buffer(3, BufferState::Unusable("4095 bytes for a 64x64 8-bit image".into()), 40)).is_none()
        );
        assert_eq!(counters(&book), [3, 3, 0, 0]);
        assert_eq!(
            book.take_losses(),
            [
                "aravis:cam: camera frame block id 65535 incomplete (MissingPackets)",
                "aravis:cam: 1 camera frame(s) before block id 2 never arrived",
                "aravis:cam: camera frame block id 0 incomplete (Timeout)",
                "aravis:cam: camera frame with stale block id 65535 dropped",
                "aravis:cam: camera frame block id 2 incomplete (MissingPackets)",
                "aravis:cam: camera frame block id 3: 4095 bytes for a 64x64 8-bit image",
            ]
        );
        assert!(book.take_losses().is_empty());
        // The next whole frame continues the numbering.
        assert_eq!(book.arrive(&buffer(4, BufferState::Complete, 50)).unwrap().name, "000005.pgm");
    }
}
