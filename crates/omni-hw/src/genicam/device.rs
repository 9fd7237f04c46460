//! The camera through Aravis (feature `aravis`): listing, opening and setting it up, and the
//! [`FrameSource`] that hands each buffer to the [`FrameBook`] and the frame writer.

use super::{
    BufferMeta, BufferState, CameraSettings, DeviceEntry, FrameBook, Roi, Trigger, check_in_range, check_pixel_format,
    check_roi, check_roi_taken, check_trigger_source,
};
use crate::client::host_time_us;
use crate::frame_writer::{FrameWriter, RawFrame};
use crate::message::TriggerEvent;
use crate::pairing::{CapturedFrame, FrameSource};
use aravis::glib;
use aravis::prelude::*;
use aravis::{Auto, BufferStatus, Camera, Stream};
use std::path::Path;
use std::time::Duration;

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

/// An open, configured camera whose acquisition runs (waiting for triggers), writing frames
/// into a directory.
pub struct AravisFrameSource {
    camera: Camera,
    stream: Stream,
    label: String,
    bit_depth: u8,
    writer: FrameWriter,
    book: FrameBook,
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
    let mut writer =
        FrameWriter::new(frames_dir, settings.frame_format, settings.writer_threads, settings.buffers.max(2))
            .map_err(|e| format!("{}: {e}", frames_dir.display()))?;
    writer.sync_each_frame(settings.sync_frames);
    camera.start_acquisition().map_err(|e| camera_error(&label, "cannot start the acquisition", e))?;
    Ok(AravisFrameSource {
        camera,
        stream,
        book: FrameBook::new(&label, &settings.trigger, settings.frame_format),
        label,
        bit_depth: settings.pixel.bit_depth(),
        writer,
    })
}

fn configure(camera: &Camera, label: &str, s: &CameraSettings) -> Result<(), String> {
    let err = |what: &str, e: glib::Error| camera_error(label, what, e);
    // An acquisition left running by an earlier session would reject the settings.
    let _ = camera.stop_acquisition();
    let formats = camera.dup_available_pixel_formats_as_strings().map_err(|e| err("cannot list pixel formats", e))?;
    let offered: Vec<&str> = formats.iter().map(|f| f.as_str()).collect();
    check_pixel_format(label, s.pixel, &offered)?;
    camera.set_pixel_format_from_string(s.pixel.name()).map_err(|e| err("cannot set the pixel format", e))?;
    if let Some(roi) = s.roi {
        set_roi(camera, label, roi)?;
    }
    if let Some(us) = s.exposure_us {
        if camera.is_exposure_auto_available().unwrap_or(false) {
            camera.set_exposure_time_auto(Auto::Off).map_err(|e| err("cannot turn auto exposure off", e))?;
        }
        let bounds = camera.exposure_time_bounds().map_err(|e| err("cannot read the exposure range", e))?;
        check_in_range(label, "exposure", us, "µs", bounds)?;
        camera.set_exposure_time(us).map_err(|e| err("cannot set the exposure", e))?;
    }
    if let Some(db) = s.gain_db {
        if camera.is_gain_auto_available().unwrap_or(false) {
            camera.set_gain_auto(Auto::Off).map_err(|e| err("cannot turn auto gain off", e))?;
        }
        let bounds = camera.gain_bounds().map_err(|e| err("cannot read the gain range", e))?;
        check_in_range(label, "gain", db, "dB", bounds)?;
        camera.set_gain(db).map_err(|e| err("cannot set the gain", e))?;
    }
    set_trigger(camera, label, &s.trigger)?;
    camera
        .set_acquisition_mode(aravis::AcquisitionMode::Continuous)
        .map_err(|e| err("cannot set continuous acquisition", e))
}

fn set_roi(camera: &Camera, label: &str, roi: Roi) -> Result<(), String> {
    let sensor = camera.sensor_size().map_err(|e| camera_error(label, "cannot read the sensor size", e))?;
    check_roi(label, roi, sensor)?;
    let (x, y, w, h) = roi.region();
    camera.set_region(x, y, w, h).map_err(|e| camera_error(label, "cannot set the ROI", e))?;
    let got = camera.region().map_err(|e| camera_error(label, "cannot read the ROI back", e))?;
    check_roi_taken(label, roi, got)
}

fn set_trigger(camera: &Camera, label: &str, trigger: &Trigger) -> Result<(), String> {
    let sources =
        camera.dup_available_trigger_sources().map_err(|e| camera_error(label, "cannot list trigger sources", e))?;
    let offered: Vec<&str> = sources.iter().map(|t| t.as_str()).collect();
    check_trigger_source(label, trigger, &offered)?;
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

/// The bookkeeping's name for a stream status: whole (then the image is checked) or broken.
fn buffer_state(status: BufferStatus) -> Option<BufferState> {
    match status {
        BufferStatus::Success => None,
        other => Some(BufferState::Broken(format!("{other:?}"))),
    }
}

impl AravisFrameSource {
    /// Takes one buffer the stream filled, queues its frame for writing if it is whole and new,
    /// and gives the buffer back to the stream.
    fn take(&mut self, buffer: aravis::Buffer) -> std::io::Result<()> {
        let (state, image) = match buffer_state(buffer.status()) {
            Some(broken) => (broken, None),
            None => {
                let image = self.image(&buffer);
                match image.check() {
                    Ok(()) => (BufferState::Complete, Some(image)),
                    Err(e) => (BufferState::Unusable(e), None),
                }
            }
        };
        let meta = BufferMeta {
            block_id: buffer.frame_id(),
            state,
            camera_ns: buffer.timestamp(),
            arrival_ns: buffer.system_timestamp(),
        };
        let result = match (self.book.arrive(&meta), image) {
            (Some(frame), Some(image)) => self.writer.submit(frame, image),
            _ => Ok(()),
        };
        self.stream.push_buffer(buffer);
        result
    }

    /// A copy of the buffer's image (the buffer goes back to the stream at once).
    fn image(&self, buffer: &aravis::Buffer) -> RawFrame {
        let (width, height) = (buffer.image_width().max(0) as u32, buffer.image_height().max(0) as u32);
        let (ptr, len) = buffer.data();
        let data = if ptr.is_null() {
            Vec::new()
        } else {
            // SAFETY: Aravis says the buffer holds `len` bytes at `ptr`; the buffer is alive and
            // not handed back to the stream until this copy is done.
            unsafe { std::slice::from_raw_parts(ptr, len) }.to_vec()
        };
        RawFrame { width, height, bit_depth: self.bit_depth, data }
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
        if !self.book.fire(ev.seq, host_time_us()) {
            return Ok(());
        }
        self.camera.software_trigger().map_err(|e| {
            std::io::Error::other(format!(
                "software trigger for trigger seq {} failed: {} (is the camera still connected?)",
                ev.seq,
                e.message()
            ))
        })
    }

    fn take_losses(&mut self) -> Vec<String> {
        self.book.take_losses()
    }

    fn finish(&mut self) -> std::io::Result<Vec<CapturedFrame>> {
        self.drain_stream()?;
        self.writer.flush(Duration::from_secs(10))
    }

    fn stats(&self) -> serde_json::Map<String, serde_json::Value> {
        let mut m = self.book.counters();
        let mut put = |k: &str, v: u64| {
            m.insert(k.into(), v.into());
        };
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stream_statuses_other_than_success_are_broken_buffers_by_name() {
        assert_eq!(buffer_state(BufferStatus::Success), None, "whole: the image is checked next");
        assert_eq!(buffer_state(BufferStatus::MissingPackets), Some(BufferState::Broken("MissingPackets".into())));
        assert_eq!(buffer_state(BufferStatus::Timeout), Some(BufferState::Broken("Timeout".into())));
        assert_eq!(buffer_state(BufferStatus::Aborted), Some(BufferState::Broken("Aborted".into())));
    }
}
