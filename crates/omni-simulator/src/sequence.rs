//! A rendered scan as files: laser frames (and their laser-off frames) as PNGs, the manifest
//! stream that lists them (`omniscan.manifest`, as the hardware capture writes it) and the
//! ground truth of their stripes (`omniscan.sim-truth`, JSON Lines). `omni-sim scan` and
//! `omni-sim rig` write these.

use crate::frame::{Frame16, FrameFormat, RgbFrame};
use crate::profile::SheetProfile;
use crate::render::{RenderOptions, render_ambient_images, render_laser_frame};
use crate::scene::Scene;
use crate::sensor::Sensor;
use crate::tools::{TruthRecord, truth_header};
use omni_formats::stream::{Frame, Header, Record, Status, StreamWriter};
use rayon::prelude::*;
use std::io::Write;
use std::path::Path;

/// The frames of a sweep: one facet, these mirror angles, these lasers on.
#[derive(Debug, Clone, Copy)]
pub struct Sweep<'a> {
    /// Mirror angle of each frame (degrees, within the facet's range).
    pub angles_deg: &'a [f64],
    pub facet: u32,
    /// Lasers on in every frame.
    pub lasers: &'a [u32],
    /// Also render a laser-off frame per angle (`ambient_NNNNNN.png`).
    pub laser_off: bool,
}

/// One rendered frame: its manifest record and its ground truth.
#[derive(Debug, Clone)]
pub struct RenderedFrame {
    pub record: Frame,
    pub truth: TruthRecord,
}

/// Renders the sweep's frames in parallel into `frames_dir` as `frame_NNNNNN.png` (NNNNNN = the
/// frame's index in the sweep), calling `on_frame` after each; the laser-off frame of frame k
/// uses the seed `opts.seed ^ (0xA3B1 + k)`. The error names the file that could not be written.
pub fn render_sweep(
    sensor: &Sensor,
    scene: &Scene,
    sweep: &Sweep,
    frames_dir: &Path,
    opts: &RenderOptions,
    on_frame: &(dyn Fn() + Sync),
) -> omni_formats::Result<Vec<RenderedFrame>> {
    render_sweep_as(sensor, scene, sweep, frames_dir, opts, FrameFormat::Png, on_frame)
}

/// [`render_sweep`] with the frames stored as `format` (`frame_NNNNNN.png`, `.pgm` or `.jpg`): a
/// colour camera's RGB frames as colour files, monochrome frames and raw Bayer mosaics as grey
/// ones. A truth record names the sheet's profile and widths when they are not the default
/// Gaussian's.
pub fn render_sweep_as(
    sensor: &Sensor,
    scene: &Scene,
    sweep: &Sweep,
    frames_dir: &Path,
    opts: &RenderOptions,
    format: FrameFormat,
    on_frame: &(dyn Fn() + Sync),
) -> omni_formats::Result<Vec<RenderedFrame>> {
    let ext = format.extension();
    sweep
        .angles_deg
        .par_iter()
        .enumerate()
        .map(|(seq, &alpha_deg)| {
            let frame = render_laser_frame(sensor, scene, alpha_deg.to_radians(), sweep.facet, sweep.lasers, opts);
            let name = format!("frame_{seq:06}.{ext}");
            write_frame(&frames_dir.join(&name), &frame.image, frame.colour.as_ref(), format)?;
            let mut record = Frame::new(seq as u64, name.clone(), alpha_deg, sweep.facet);
            record.lasers = sweep.lasers.to_vec();
            if sweep.laser_off {
                let ambient_name = format!("ambient_{seq:06}.{ext}");
                let seeded = RenderOptions { seed: opts.seed ^ (0xA3B1 + seq as u64), ..opts.clone() };
                let (grey, colour) = render_ambient_images(sensor, scene, &seeded);
                write_frame(&frames_dir.join(&ambient_name), &grey, colour.as_ref(), format)?;
                record.ambient_path = Some(ambient_name);
            }
            on_frame();
            let mut truth = TruthRecord::new(seq as u64, &name, alpha_deg, sweep.facet, &frame.truth);
            if opts.profile != SheetProfile::Gaussian || opts.stripe_fwhm_px.is_some() {
                truth = truth.with_sheet(opts.profile, &frame.sheet_fwhm_mm);
            }
            Ok(RenderedFrame { truth, record })
        })
        .collect()
}

/// Writes a frame as `format`: the colour frame if there is one, else the grey frame (PNG exactly
/// as [`Frame16::to_png`] writes it).
fn write_frame(
    path: &Path,
    grey: &Frame16,
    colour: Option<&RgbFrame>,
    format: FrameFormat,
) -> omni_formats::Result<()> {
    if colour.is_none() && format == FrameFormat::Png {
        return grey.to_png(path);
    }
    let bytes = match colour {
        Some(c) => c.encode(format),
        None => grey.encode(format),
    }
    .map_err(|e| omni_formats::Error::io(path.display().to_string(), &std::io::Error::other(e)))?;
    omni_formats::io::write_atomic(path, |w| w.write_all(&bytes))
}

/// Writes the manifest stream of `frames` (header naming `producer`, the frames directory and the
/// calibration files; the frames; a complete status) to `path`: a file atomically, `-` stdout.
pub fn write_manifest(
    path: &Path,
    producer: &str,
    frames_dir: &Path,
    camera: &Path,
    scanner: &Path,
    frames: &[RenderedFrame],
) -> omni_formats::Result<()> {
    let mut header = Header::new(producer);
    header.frames_dir = Some(omni_formats::stream::frames_dir_for_manifest(path, frames_dir));
    header.camera = Some(camera.display().to_string());
    header.scanner = Some(scanner.display().to_string());
    let status = Status::complete(frames.len() as u64);
    let write = |w: &mut dyn Write| -> std::io::Result<()> {
        let mut s = StreamWriter::new(w, "manifest");
        s.flush_each = false;
        let io = |e: omni_formats::Error| std::io::Error::other(e.to_string());
        s.write(&Record::Header(header.clone())).map_err(io)?;
        for f in frames {
            s.write(&Record::Frame(Box::new(f.record.clone()))).map_err(io)?;
        }
        s.write(&Record::Status(status.clone())).map_err(io)?;
        s.flush().map_err(io)
    };
    if path == Path::new("-") {
        let stdout = std::io::stdout();
        let mut lock = stdout.lock();
        write(&mut lock).map_err(|e| omni_formats::Error::io("stdout", &e))
    } else {
        omni_formats::io::write_atomic(path, |w| write(w))
    }
}

/// Writes the ground truth of `frames` (JSON Lines: [`truth_header`] naming `scene_name`, then one
/// [`TruthRecord`] per frame) to `path` atomically.
pub fn write_truth(path: &Path, scene_name: &str, frames: &[RenderedFrame]) -> omni_formats::Result<()> {
    omni_formats::io::write_atomic(path, |w| {
        serde_json::to_writer(&mut *w, &truth_header(scene_name)).map_err(std::io::Error::other)?;
        w.write_all(b"\n")?;
        for f in frames {
            serde_json::to_writer(&mut *w, &f.truth).map_err(std::io::Error::other)?;
            w.write_all(b"\n")?;
        }
        Ok(())
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use omni_formats::stream::StreamReader;
    use std::sync::atomic::{AtomicUsize, Ordering};

    /// The paper bench's plane (400 × 300 mm, 500 mm out on +x) seen by a 128 px paper sensor.
    fn bench() -> (Sensor, Scene) {
        let text = std::fs::read(concat!(env!("CARGO_MANIFEST_DIR"), "/../../testdata/scenes/plane.json")).unwrap();
        let file = omni_formats::parse_doc(&text, "plane.json").unwrap();
        (Sensor::paper_scaled(128), Scene::from_file(file).unwrap())
    }

    #[test]
    fn a_sweep_writes_its_frames_manifest_and_truth() {
        let dir = tempfile::tempdir().unwrap();
        let (sensor, scene) = bench();
        let sweep = Sweep { angles_deg: &[16.0, 18.0, 20.0], facet: 3, lasers: &[0, 1], laser_off: true };
        let opts = RenderOptions::default();
        let calls = AtomicUsize::new(0);
        let frames = render_sweep(&sensor, &scene, &sweep, dir.path(), &opts, &|| {
            calls.fetch_add(1, Ordering::Relaxed);
        })
        .unwrap();
        assert_eq!(calls.load(Ordering::Relaxed), 3);
        assert!(frames.iter().all(|f| !f.truth.points.is_empty()), "the stripes cross the plane");
        for (k, (f, alpha)) in frames.iter().zip([16.0, 18.0, 20.0]).enumerate() {
            let name = format!("frame_{k:06}.png");
            assert_eq!((f.record.seq, f.record.path.as_str(), f.record.alpha_deg), (k as u64, name.as_str(), alpha));
            assert_eq!((f.record.facet, f.record.lasers.as_slice()), (3, &[0, 1][..]));
            assert_eq!(f.record.ambient_path, Some(format!("ambient_{k:06}.png")));
            assert_eq!((f.truth.seq, f.truth.path.as_str(), f.truth.facet), (k as u64, name.as_str(), 3));
            assert!(dir.path().join(&name).exists() && dir.path().join(format!("ambient_{k:06}.png")).exists());
        }

        let manifest = dir.path().join("scan.jsonl");
        write_manifest(&manifest, "test 1", dir.path(), Path::new("c.json"), Path::new("s.json"), &frames).unwrap();
        let records: Vec<Record> = StreamReader::open(&manifest).unwrap().collect::<Result<_, _>>().unwrap();
        assert_eq!(records.len(), 5);
        let Record::Header(h) = &records[0] else { panic!("{:?}", records[0]) };
        assert_eq!((h.camera.as_deref(), h.scanner.as_deref()), (Some("c.json"), Some("s.json")));
        assert_eq!(h.frames_dir, Some(dir.path().display().to_string()));
        let Record::Frame(f) = &records[2] else { panic!("{:?}", records[2]) };
        assert_eq!(**f, frames[1].record);
        let Record::Status(s) = &records[4] else { panic!("{:?}", records[4]) };
        assert!(s.complete && s.frames == 3 && s.frames_missing == 0);

        let truth = dir.path().join("truth.jsonl");
        write_truth(&truth, "plane", &frames).unwrap();
        let text = std::fs::read_to_string(&truth).unwrap();
        let lines: Vec<serde_json::Value> = text.lines().map(|l| serde_json::from_str(l).unwrap()).collect();
        assert_eq!(lines[0], truth_header("plane"));
        let back: Vec<TruthRecord> = lines[1..].iter().map(|v| serde_json::from_value(v.clone()).unwrap()).collect();
        assert_eq!(back, frames.iter().map(|f| f.truth.clone()).collect::<Vec<_>>());
    }

    #[test]
    fn an_unwritable_frames_directory_is_named() {
        let dir = tempfile::tempdir().unwrap();
        let (sensor, scene) = bench();
        let missing = dir.path().join("missing");
        let sweep = Sweep { angles_deg: &[16.0], facet: 0, lasers: &[0], laser_off: false };
        let err = render_sweep(&sensor, &scene, &sweep, &missing, &RenderOptions::default(), &|| {}).unwrap_err();
        assert!(err.to_string().contains(&missing.join("frame_000000.png").display().to_string()), "{err}");
    }
}
