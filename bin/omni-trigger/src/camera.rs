//! `--camera aravis:ID` and `omni-trigger cameras`: GenICam cameras through Aravis (cargo
//! feature `aravis`). Without the feature the flags parse and say how to get it.

use clap::Args;
use omni_cli::{CliError, CliResult};
use omni_hw::frame_writer::FrameFormat;
use omni_hw::pairing::FrameSource;
use std::path::Path;

/// The camera omniscan drives itself (instead of the camera software writing into --frames).
#[derive(Args)]
pub struct CameraArgs {
    /// Capture from a GenICam camera: `aravis:DEVICE_ID` (an id from `omni-trigger cameras`, or a
    /// GigE camera's IP address). Frames are written into --frames as they arrive.
    #[arg(long, value_name = "aravis:DEVICE_ID")]
    pub camera: Option<String>,
    /// Camera trigger: `Line0`, `Line1`, ... (the input wired to the controller's trigger output,
    /// rising edge) or `software` (omni-trigger fires the camera for every trigger event; for
    /// tests and rigs without a trigger wire).
    #[arg(long, default_value = "software", requires = "camera")]
    pub trigger: String,
    /// Pixel format: Mono8 or Mono16.
    #[arg(long, default_value = "Mono8", requires = "camera")]
    pub pixel_format: String,
    /// Exposure time (µs); default: the camera's current one.
    #[arg(long, requires = "camera", allow_negative_numbers = true)]
    pub exposure_us: Option<f64>,
    /// Analog gain (dB); default: the camera's current one.
    #[arg(long, requires = "camera", allow_negative_numbers = true)]
    pub gain_db: Option<f64>,
    /// Region of interest on the sensor: X,Y,WIDTH,HEIGHT (px); default: the camera's current one.
    #[arg(long, requires = "camera", allow_hyphen_values = true)]
    pub roi: Option<String>,
    /// File format of captured frames: `pgm` (uncompressed, keeps up with the camera) or `png`.
    #[arg(long, default_value = "pgm", requires = "camera")]
    pub frame_format: String,
    /// Stream buffers, each one frame: the memory the camera stream may hold.
    #[arg(long, default_value_t = 16, requires = "camera", allow_negative_numbers = true)]
    pub camera_buffers: usize,
}

impl CameraArgs {
    /// The device id of `--camera aravis:ID`.
    fn device_id(&self) -> CliResult<Option<&str>> {
        let Some(spec) = &self.camera else { return Ok(None) };
        match spec.split_once(':') {
            Some(("aravis", id)) if !id.is_empty() => Ok(Some(id)),
            _ => Err(CliError::usage(format!(
                "--camera {spec:?}: expected aravis:DEVICE_ID (the only camera library omniscan drives)"
            ))),
        }
    }

    fn frame_format(&self) -> CliResult<FrameFormat> {
        FrameFormat::parse(&self.frame_format).map_err(|e| CliError::usage(format!("--frame-format: {e}")))
    }

    /// The manifest header's `genicam` object, if a camera is driven.
    pub fn header(&self) -> Option<serde_json::Value> {
        let spec = self.camera.as_ref()?;
        Some(serde_json::json!({
            "device": spec, "trigger": self.trigger, "pixel_format": self.pixel_format,
            "exposure_us": self.exposure_us, "gain_db": self.gain_db, "roi": self.roi,
            "frame_format": self.frame_format.to_ascii_lowercase(),
        }))
    }

    /// Opens and sets up the camera (`None` without --camera), acquisition started and waiting
    /// for triggers.
    #[cfg(feature = "aravis")]
    pub fn open(&self, frames: &Path) -> CliResult<Option<Box<dyn FrameSource>>> {
        use omni_hw::genicam;
        let Some(id) = self.device_id()? else { return Ok(None) };
        fn usage(flag: &'static str) -> impl Fn(String) -> CliError {
            move |e| CliError::usage(format!("--{flag}: {e}"))
        }
        let settings = genicam::CameraSettings {
            pixel: genicam::Pixel::parse(&self.pixel_format).map_err(usage("pixel-format"))?,
            exposure_us: positive("exposure-us", self.exposure_us)?,
            gain_db: finite("gain-db", self.gain_db)?,
            roi: self.roi.as_deref().map(genicam::Roi::parse).transpose().map_err(usage("roi"))?,
            trigger: genicam::Trigger::parse(&self.trigger).map_err(usage("trigger"))?,
            buffers: match self.camera_buffers {
                n @ 2..=1024 => n,
                n => return Err(CliError::usage(format!("--camera-buffers must be in 2..=1024, got {n}"))),
            },
            frame_format: self.frame_format()?,
            writer_threads: std::thread::available_parallelism().map_or(2, |n| n.get().clamp(1, 4)),
        };
        let source = genicam::open(id, &settings, frames).map_err(CliError::new)?;
        Ok(Some(Box::new(source)))
    }

    #[cfg(not(feature = "aravis"))]
    pub fn open(&self, _frames: &Path) -> CliResult<Option<Box<dyn FrameSource>>> {
        if self.device_id()?.is_none() {
            return Ok(None);
        }
        self.frame_format()?;
        Err(not_built())
    }
}

#[cfg(feature = "aravis")]
fn positive(flag: &str, v: Option<f64>) -> CliResult<Option<f64>> {
    match v {
        Some(x) if !(x > 0.0 && x.is_finite()) => Err(CliError::usage(format!("--{flag} must be positive"))),
        v => Ok(v),
    }
}

#[cfg(feature = "aravis")]
fn finite(flag: &str, v: Option<f64>) -> CliResult<Option<f64>> {
    match v {
        Some(x) if !x.is_finite() => Err(CliError::usage(format!("--{flag} must be a number"))),
        v => Ok(v),
    }
}

#[cfg(not(feature = "aravis"))]
fn not_built() -> CliError {
    CliError::new(
        "this omni-trigger was built without GenICam support: rebuild with `cargo build --release -p omni-trigger \
         --features aravis` (needs libaravis-dev), or let the camera's own software write into --frames",
    )
}

/// List the GenICam (GigE Vision, USB3 Vision) cameras Aravis finds.
#[derive(Args)]
#[command(after_help = "Each line: device id (pass it as --camera aravis:ID), vendor, model, serial number, \
    interface, address. GigE cameras are found by a discovery broadcast on every network interface; a camera on \
    another subnet can still be opened by its IP address (--camera aravis:192.168.1.20).\n\n\
    Examples:\n  omni-trigger cameras\n  omni-trigger cameras --json")]
pub struct CamerasArgs {
    /// One JSON object per line instead of a table.
    #[arg(long)]
    json: bool,
}

#[cfg(feature = "aravis")]
pub fn cameras(a: CamerasArgs) -> CliResult {
    use std::io::Write;
    let devices = omni_hw::genicam::list_devices();
    let mut out = std::io::stdout().lock();
    if a.json {
        for d in &devices {
            let v = serde_json::json!({"id": d.id, "vendor": d.vendor, "model": d.model, "serial": d.serial,
                "interface": d.interface, "address": d.address});
            writeln!(out, "{v}")?;
        }
    } else if devices.is_empty() {
        eprintln!("omni-trigger cameras: no GenICam camera found");
    } else {
        writeln!(out, "{:<32} {:<16} {:<20} {:<16} {:<12} address", "id", "vendor", "model", "serial", "interface")?;
        for d in &devices {
            writeln!(
                out,
                "{:<32} {:<16} {:<20} {:<16} {:<12} {}",
                d.id, d.vendor, d.model, d.serial, d.interface, d.address
            )?;
        }
    }
    out.flush()?;
    Ok(())
}

#[cfg(not(feature = "aravis"))]
pub fn cameras(_a: CamerasArgs) -> CliResult {
    Err(not_built())
}
