//! GenICam cameras (GigE Vision, USB3 Vision) driven through Aravis: listing, setup, and a
//! [`FrameSource`] that writes every frame the camera delivers and names the trigger it
//! answers. Feature `aravis` (needs the system `libaravis-0.8`).
//!
//! Frames are numbered by the camera's frame id ([`BlockIdUnwrapper`]: GigE Vision's 16-bit
//! block id wraps), so frames lost on the way are counted exactly. Timestamps are the camera's
//! exposure timestamps mapped onto the host clock (the smallest "arrival − stamp" difference
//! seen, like the controller clock in [`crate::pairing`]). With the software trigger the host
//! fires the camera for each controller trigger event and records which trigger each firing
//! was for ([`TriggerLedger`]); each frame then names its trigger, and the pairing still checks
//! the timestamp. With a hardware line the pairing goes by timestamp alone.

use crate::client::host_time_us;
use crate::frame_id::{BlockIdUnwrapper, LossCount, TriggerLedger};
use crate::frame_writer::{FrameFormat, FrameWriter, RawFrame};
use crate::message::TriggerEvent;
use crate::pairing::{CapturedFrame, FrameSource};
use aravis::glib;
use aravis::prelude::*;
use aravis::{Auto, BufferStatus, Camera, Stream};
use std::path::{Path, PathBuf};
use std::time::Duration;

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

/// Every GenICam device Aravis finds (GigE discovery broadcasts on each interface, USB
/// enumeration).
pub fn list_devices() -> Vec<DeviceEntry> {
    let text = |p: *const std::ffi::c_char| {
        if p.is_null() {
            String::new()
        } else {
            // SAFETY: Aravis returns NUL-terminated strings it owns until the next update.
            unsafe { std::ffi::CStr::from_ptr(p) }.to_string_lossy().into_owned()
        }
    };
    // SAFETY: the device list is global state of libaravis; this process reads it from one
    // thread, and each index is below the count of the update just made.
    unsafe {
        aravis_sys::arv_update_device_list();
        (0..aravis_sys::arv_get_n_devices())
            .map(|i| DeviceEntry {
                id: text(aravis_sys::arv_get_device_id(i)),
                vendor: text(aravis_sys::arv_get_device_vendor(i)),
                model: text(aravis_sys::arv_get_device_model(i)),
                serial: text(aravis_sys::arv_get_device_serial_nbr(i)),
                interface: text(aravis_sys::arv_get_device_protocol(i)),
                address: text(aravis_sys::arv_get_device_address(i)),
            })
            .collect()
    }
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

    fn bit_depth(self) -> u8 {
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
        }
    }
}

/// An open, configured camera whose acquisition runs (waiting for triggers), writing frames
/// into a directory.
pub struct AravisFrameSource {
    camera: Camera,
    stream: Stream,
    label: String,
    bit_depth: u8,
    writer: FrameWriter,
    ids: BlockIdUnwrapper,
    /// Software trigger mode: the triggers fired, to name each frame's trigger.
    ledger: Option<TriggerLedger>,
    /// Host clock − camera clock (ns), the smallest seen.
    clock_offset_ns: Option<i128>,
    losses: Vec<String>,
    received: u64,
    broken: LossCount,
    software_triggers: u64,
}

fn camera_error(label: &str, what: &str, e: glib::Error) -> String {
    format!("{label}: {what}: {}", e.message())
}

/// Opens and configures the camera `device_id` (an id from [`list_devices`], or a GigE
/// camera's IP address), starts its acquisition in trigger mode, and writes its frames into
/// `frames_dir` in `settings.frame_format`. Every setting is checked against what the camera
/// offers; any refusal is an error here, before a controller is armed.
pub fn open(device_id: &str, settings: &CameraSettings, frames_dir: &Path) -> Result<AravisFrameSource, String> {
    let label = format!("aravis:{device_id}");
    let camera = Camera::new(Some(device_id)).map_err(|e| {
        format!("{label}: cannot open the camera: {} (`omni-trigger cameras` lists those found)", e.message())
    })?;
    configure(&camera, &label, settings)?;
    let stream = camera.create_stream().map_err(|e| camera_error(&label, "cannot create the stream", e))?;
    let payload = camera.payload().map_err(|e| camera_error(&label, "cannot read the payload size", e))?;
    for _ in 0..settings.buffers.max(2) {
        stream.push_buffer(aravis::Buffer::new_allocate(payload as usize));
    }
    let writer = FrameWriter::new(frames_dir, settings.frame_format, settings.writer_threads, settings.buffers.max(2))
        .map_err(|e| format!("{}: {e}", frames_dir.display()))?;
    camera.start_acquisition().map_err(|e| camera_error(&label, "cannot start the acquisition", e))?;
    Ok(AravisFrameSource {
        camera,
        stream,
        label,
        bit_depth: settings.pixel.bit_depth(),
        writer,
        ids: BlockIdUnwrapper::default(),
        ledger: (settings.trigger == Trigger::Software).then(TriggerLedger::default),
        clock_offset_ns: None,
        losses: Vec::new(),
        received: 0,
        broken: LossCount::default(),
        software_triggers: 0,
    })
}

fn configure(camera: &Camera, label: &str, s: &CameraSettings) -> Result<(), String> {
    let err = |what: &str, e: glib::Error| camera_error(label, what, e);
    // An acquisition left running by an earlier session would reject the settings.
    let _ = camera.stop_acquisition();
    let formats = camera.dup_available_pixel_formats_as_strings().map_err(|e| err("cannot list pixel formats", e))?;
    if !formats.iter().any(|f| f.as_str() == s.pixel.name()) {
        let offered: Vec<&str> = formats.iter().map(|f| f.as_str()).collect();
        return Err(format!(
            "{label}: the camera does not offer pixel format {} (it offers: {})",
            s.pixel.name(),
            offered.join(", ")
        ));
    }
    camera.set_pixel_format_from_string(s.pixel.name()).map_err(|e| err("cannot set the pixel format", e))?;
    if let Some(roi) = s.roi {
        set_roi(camera, label, roi)?;
    }
    if let Some(us) = s.exposure_us {
        if camera.is_exposure_auto_available().unwrap_or(false) {
            camera.set_exposure_time_auto(Auto::Off).map_err(|e| err("cannot turn auto exposure off", e))?;
        }
        let (lo, hi) = camera.exposure_time_bounds().map_err(|e| err("cannot read the exposure range", e))?;
        if !(lo..=hi).contains(&us) {
            return Err(format!("{label}: exposure {us} µs outside the camera's range {lo}..{hi} µs"));
        }
        camera.set_exposure_time(us).map_err(|e| err("cannot set the exposure", e))?;
    }
    if let Some(db) = s.gain_db {
        if camera.is_gain_auto_available().unwrap_or(false) {
            camera.set_gain_auto(Auto::Off).map_err(|e| err("cannot turn auto gain off", e))?;
        }
        let (lo, hi) = camera.gain_bounds().map_err(|e| err("cannot read the gain range", e))?;
        if !(lo..=hi).contains(&db) {
            return Err(format!("{label}: gain {db} dB outside the camera's range {lo}..{hi} dB"));
        }
        camera.set_gain(db).map_err(|e| err("cannot set the gain", e))?;
    }
    set_trigger(camera, label, &s.trigger)?;
    camera
        .set_acquisition_mode(aravis::AcquisitionMode::Continuous)
        .map_err(|e| err("cannot set continuous acquisition", e))
}

fn set_roi(camera: &Camera, label: &str, roi: Roi) -> Result<(), String> {
    let (sw, sh) = camera.sensor_size().map_err(|e| camera_error(label, "cannot read the sensor size", e))?;
    let inside = |o: u32, len: u32, side: i32| o as u64 + len as u64 <= side.max(0) as u64;
    if !inside(roi.x, roi.width, sw) || !inside(roi.y, roi.height, sh) {
        return Err(format!(
            "{label}: ROI {},{},{},{} lies outside the {sw}x{sh} px sensor",
            roi.x, roi.y, roi.width, roi.height
        ));
    }
    let to_i32 = |v: u32| i32::try_from(v).unwrap_or(i32::MAX);
    camera
        .set_region(to_i32(roi.x), to_i32(roi.y), to_i32(roi.width), to_i32(roi.height))
        .map_err(|e| camera_error(label, "cannot set the ROI", e))?;
    let got = camera.region().map_err(|e| camera_error(label, "cannot read the ROI back", e))?;
    if got != (to_i32(roi.x), to_i32(roi.y), to_i32(roi.width), to_i32(roi.height)) {
        return Err(format!(
            "{label}: the camera set the ROI to {},{},{},{} instead of {},{},{},{} (check its size increments)",
            got.0, got.1, got.2, got.3, roi.x, roi.y, roi.width, roi.height
        ));
    }
    Ok(())
}

fn set_trigger(camera: &Camera, label: &str, trigger: &Trigger) -> Result<(), String> {
    let sources =
        camera.dup_available_trigger_sources().map_err(|e| camera_error(label, "cannot list trigger sources", e))?;
    if !sources.iter().any(|t| t.as_str() == trigger.source()) {
        let offered: Vec<&str> = sources.iter().map(|t| t.as_str()).collect();
        return Err(format!(
            "{label}: the camera refuses trigger source {} (it offers: {})",
            trigger.source(),
            if offered.is_empty() { "none: no trigger mode".to_string() } else { offered.join(", ") }
        ));
    }
    // Cameras that poll for triggers at their frame rate (Aravis's fake camera) answer sooner
    // at the highest rate; a camera without the feature simply keeps its own. First, because
    // Aravis's frame rate setter turns the trigger mode off.
    if camera.is_frame_rate_available().unwrap_or(false)
        && let Ok((_, max)) = camera.frame_rate_bounds()
    {
        let _ = camera.set_frame_rate(max);
    }
    // FrameStart on the source, rising edge, TriggerMode On.
    camera
        .set_trigger(trigger.source())
        .map_err(|e| camera_error(label, &format!("the camera refuses trigger mode on {}", trigger.source()), e))
}

impl AravisFrameSource {
    /// Takes one buffer the stream filled, queues its frame for writing, and gives the buffer
    /// back to the stream.
    fn take(&mut self, buffer: aravis::Buffer) -> std::io::Result<()> {
        let raw_id = buffer.frame_id();
        let status = buffer.status();
        // Id 0 is reserved: an incomplete buffer carries it when none of its leader arrived.
        let unnamed = raw_id == 0 && status != BufferStatus::Success;
        let index = match if unnamed { None } else { self.ids.push(raw_id) } {
            Some((index, skipped)) => {
                if skipped > 0 {
                    self.broken.skipped(index - skipped..index);
                    self.losses.push(format!(
                        "{}: {skipped} camera frame(s) before block id {raw_id} never arrived",
                        self.label
                    ));
                }
                Some(index)
            }
            None => None,
        };
        let result = match (status, index) {
            (BufferStatus::Success, Some(index)) => self.write(&buffer, index, raw_id),
            (BufferStatus::Success, None) => {
                self.losses.push(format!("{}: camera frame with stale block id {raw_id} dropped", self.label));
                Ok(())
            }
            (other, _) => {
                match index {
                    Some(index) => self.broken.incomplete_named(index),
                    None if unnamed => self.broken.incomplete_unnamed(),
                    None => self.broken.incomplete_late(self.ids.index_of(raw_id)),
                }
                self.losses.push(format!("{}: camera frame block id {raw_id} incomplete ({other:?})", self.label));
                Ok(())
            }
        };
        self.stream.push_buffer(buffer);
        result
    }

    fn write(&mut self, buffer: &aravis::Buffer, index: u64, raw_id: u64) -> std::io::Result<()> {
        self.received += 1;
        let (width, height) = (buffer.image_width().max(0) as u32, buffer.image_height().max(0) as u32);
        let (ptr, len) = buffer.data();
        let data = if ptr.is_null() {
            Vec::new()
        } else {
            // SAFETY: Aravis says the buffer holds `len` bytes at `ptr`; the buffer is alive and
            // not handed back to the stream until this copy is done.
            unsafe { std::slice::from_raw_parts(ptr, len) }.to_vec()
        };
        let image = RawFrame { width, height, bit_depth: self.bit_depth, data };
        if let Err(e) = image.check() {
            self.broken.incomplete_named(index);
            self.losses.push(format!("{}: camera frame block id {raw_id}: {e}", self.label));
            return Ok(());
        }
        let camera_ns = buffer.timestamp();
        let arrival_ns = buffer.system_timestamp();
        let time_us = self.host_time_us(camera_ns, arrival_ns);
        let mut frame = CapturedFrame::new(PathBuf::new(), self.writer.file_name(&format!("{index:06}")), time_us);
        frame.trigger_seq = self.ledger.as_mut().and_then(|l| l.answer(time_us));
        frame.extra.insert("camera_frame".into(), index.into());
        frame.extra.insert("camera_block_id".into(), raw_id.into());
        frame.extra.insert("camera_timestamp_ns".into(), camera_ns.into());
        self.writer.submit(frame, image)
    }

    /// The exposure's host-clock time (µs): the camera stamp plus the smallest arrival − stamp
    /// difference seen; the arrival time if the camera does not stamp.
    fn host_time_us(&mut self, camera_ns: u64, arrival_ns: u64) -> i64 {
        if camera_ns == 0 {
            return (arrival_ns / 1000) as i64;
        }
        let offset = arrival_ns as i128 - camera_ns as i128;
        let best = self.clock_offset_ns.map_or(offset, |o| o.min(offset));
        self.clock_offset_ns = Some(best);
        ((camera_ns as i128 + best) / 1000) as i64
    }

    fn drain_stream(&mut self) -> std::io::Result<()> {
        while let Some(buffer) = self.stream.try_pop_buffer() {
            self.take(buffer)?;
        }
        Ok(())
    }
}

impl FrameSource for AravisFrameSource {
    fn poll(&mut self) -> std::io::Result<Vec<CapturedFrame>> {
        self.drain_stream()?;
        self.writer.written()
    }

    fn describe(&self) -> String {
        self.label.clone()
    }

    fn on_trigger(&mut self, ev: &TriggerEvent, _received_us: i64) -> std::io::Result<()> {
        let Some(ledger) = self.ledger.as_mut() else { return Ok(()) };
        ledger.record(ev.seq, host_time_us());
        self.software_triggers += 1;
        self.camera.software_trigger().map_err(|e| {
            std::io::Error::other(format!(
                "software trigger for trigger seq {} failed: {} (is the camera still connected?)",
                ev.seq,
                e.message()
            ))
        })
    }

    fn take_losses(&mut self) -> Vec<String> {
        std::mem::take(&mut self.losses)
    }

    fn finish(&mut self) -> std::io::Result<Vec<CapturedFrame>> {
        self.drain_stream()?;
        self.writer.flush(Duration::from_secs(10))
    }

    fn stats(&self) -> serde_json::Map<String, serde_json::Value> {
        let mut m = serde_json::Map::new();
        let mut put = |k: &str, v: u64| {
            m.insert(k.into(), v.into());
        };
        put("camera_frames_received", self.received);
        put("camera_frames_incomplete", self.broken.incomplete);
        put("camera_frames_lost", self.broken.lost);
        put("camera_software_triggers", self.software_triggers);
        let (_, failures, underruns) = self.stream.statistics();
        put("camera_stream_failures", failures);
        put("camera_stream_underruns", underruns);
        if self.camera.is_gv_device() {
            put("camera_packets_missing", self.stream.info_uint64_by_name("n_missing_packets"));
            put("camera_packets_resent", self.stream.info_uint64_by_name("n_resent_packets"));
        }
        m
    }
}

impl Drop for AravisFrameSource {
    fn drop(&mut self) {
        let _ = self.camera.stop_acquisition();
    }
}
