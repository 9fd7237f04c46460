//! `--camera aravis:ID` and `omni-trigger cameras`: GenICam cameras through Aravis (cargo
//! feature `aravis`). Without the feature the flags parse and say how to get it.

use clap::Args;
use omni_cli::{CliError, CliResult};
use omni_hw::frame_writer::FrameFormat;
use omni_hw::genicam;
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
    /// Sync each frame file to disk before it goes into the manifest, so that a power cut loses
    /// no listed frame (off by default: it costs capture rate; the frames are complete files
    /// either way).
    #[arg(long, requires = "camera")]
    pub sync_frames: bool,
}

impl CameraArgs {
    /// The device id of `--camera aravis:ID`.
    fn device_id(&self) -> CliResult<Option<&str>> {
        let Some(spec) = &self.camera else { return Ok(None) };
        genicam::parse_camera_spec(spec).map(Some).map_err(|e| CliError::usage(format!("--camera {e}")))
    }

    fn frame_format(&self) -> CliResult<FrameFormat> {
        FrameFormat::parse(&self.frame_format).map_err(|e| CliError::usage(format!("--frame-format: {e}")))
    }

    /// The camera settings the flags ask for, each checked on its own (a usage error names the
    /// flag); whether the camera offers them is checked when it is opened.
    fn settings(&self) -> CliResult<genicam::CameraSettings> {
        fn usage(flag: &'static str) -> impl Fn(String) -> CliError {
            move |e| CliError::usage(format!("--{flag}: {e}"))
        }
        Ok(genicam::CameraSettings {
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
            sync_frames: self.sync_frames,
        })
    }

    /// The manifest header's `genicam` object, if a camera is driven.
    pub fn header(&self) -> Option<serde_json::Value> {
        let spec = self.camera.as_ref()?;
        Some(serde_json::json!({
            "device": spec, "trigger": self.trigger, "pixel_format": self.pixel_format,
            "exposure_us": self.exposure_us, "gain_db": self.gain_db, "roi": self.roi,
            "frame_format": self.frame_format.to_ascii_lowercase(), "sync_frames": self.sync_frames,
        }))
    }

    /// Opens and sets up the camera (`None` without --camera), acquisition started and waiting
    /// for triggers.
    #[cfg(feature = "aravis")]
    pub fn open(&self, frames: &Path) -> CliResult<Option<Box<dyn FrameSource>>> {
        let Some(id) = self.device_id()? else { return Ok(None) };
        let source = genicam::open(id, &self.settings()?, frames).map_err(CliError::new)?;
        Ok(Some(Box::new(source)))
    }

    /// Without the feature the flags are still checked, then the build is named as the problem.
    #[cfg(not(feature = "aravis"))]
    pub fn open(&self, _frames: &Path) -> CliResult<Option<Box<dyn FrameSource>>> {
        if self.device_id()?.is_none() {
            return Ok(None);
        }
        self.settings()?;
        Err(not_built())
    }
}

fn positive(flag: &str, v: Option<f64>) -> CliResult<Option<f64>> {
    v.map(|x| omni_cli::positive(&format!("--{flag}"), x)).transpose()
}

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

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    #[derive(Parser)]
    struct Flags {
        #[command(flatten)]
        camera: CameraArgs,
    }

    fn args(flags: &[&str]) -> CameraArgs {
        Flags::try_parse_from(std::iter::once("t").chain(flags.iter().copied())).unwrap().camera
    }

    fn settings_error(flags: &[&str]) -> String {
        args(flags).settings().unwrap_err().message().to_string()
    }

    #[test]
    fn flags_become_camera_settings() {
        let a = args(&[
            "--camera",
            "aravis:10.0.0.7",
            "--trigger",
            "Line1",
            "--pixel-format",
            "mono16",
            "--exposure-us",
            "500",
            "--gain-db",
            "-1.5",
            "--roi",
            "0,8,1024,1016",
            "--frame-format",
            "PNG",
            "--camera-buffers",
            "8",
            "--sync-frames",
        ]);
        assert_eq!(a.device_id().unwrap(), Some("10.0.0.7"));
        let s = a.settings().unwrap();
        assert_eq!(s.pixel, genicam::Pixel::Mono16);
        assert_eq!((s.exposure_us, s.gain_db), (Some(500.0), Some(-1.5)));
        assert_eq!(s.roi, Some(genicam::Roi { x: 0, y: 8, width: 1024, height: 1016 }));
        assert_eq!(s.trigger, genicam::Trigger::Line("Line1".into()));
        assert_eq!((s.buffers, s.frame_format, s.sync_frames), (8, FrameFormat::Png, true));
        assert_eq!(a.header().unwrap()["frame_format"], "png");
        // The defaults: software trigger, Mono8, PGM, the camera's own exposure, gain and ROI.
        let s = args(&["--camera", "aravis:x"]).settings().unwrap();
        assert_eq!(
            (s.pixel, s.trigger, s.frame_format),
            (genicam::Pixel::Mono8, genicam::Trigger::Software, FrameFormat::Pgm)
        );
        assert_eq!((s.exposure_us, s.gain_db, s.roi, s.buffers, s.sync_frames), (None, None, None, 16, false));
        assert_eq!(args(&[]).device_id().unwrap(), None);
        assert!(args(&[]).header().is_none());
    }

    #[test]
    fn each_bad_flag_is_named() {
        let cam = ["--camera", "aravis:x"];
        let with = |more: &[&'static str]| [&cam[..], more].concat();
        assert!(settings_error(&with(&["--exposure-us", "0"])).contains("--exposure-us must be positive"));
        assert!(settings_error(&with(&["--exposure-us", "-3"])).contains("--exposure-us must be positive"));
        assert!(settings_error(&with(&["--gain-db", "NaN"])).contains("--gain-db must be a number"));
        assert!(
            settings_error(&with(&["--camera-buffers", "1"])).contains("--camera-buffers must be in 2..=1024, got 1")
        );
        assert!(settings_error(&with(&["--roi", "0,0,10"])).starts_with("--roi: bad ROI"));
        assert!(settings_error(&with(&["--pixel-format", "Mono12"])).starts_with("--pixel-format: unsupported"));
        assert!(settings_error(&with(&["--trigger", "Line 0"])).starts_with("--trigger: bad trigger"));
        assert!(settings_error(&with(&["--frame-format", "tiff"])).starts_with("--frame-format: unknown frame format"));
        let e = args(&["--camera", "basler:1"]).device_id().unwrap_err();
        assert!(e.message().starts_with("--camera \"basler:1\": expected aravis:DEVICE_ID"), "{}", e.message());
        // Camera flags need --camera.
        assert!(Flags::try_parse_from(["t", "--roi", "0,0,8,8"]).is_err());
    }
}
