//! Writing captured camera frames to image files, on worker threads, in capture order.
//!
//! A frame is written atomically (temporary file + rename, so `omni-ridge` reading the
//! directory never sees half a file), with its modification time set to the exposure time.
//! Frames are not synced one by one unless asked ([`FrameWriter::sync_each_frame`], `scan
//! --sync-frames`): the rename already makes every listed file whole for readers and safe from a
//! crash of the process, the kernel writes it back, and a sync per frame costs capture rate,
//! so only a power cut can lose the last frames, as it can the manifest written beside them.
//! Formats: PNG (compressed, slow to encode at camera rates) and binary PGM (`P5`: a text header
//! and the raw samples, 16-bit big-endian), which every reader of `omni_vision::image_io` loads.

use crate::pairing::CapturedFrame;
use std::borrow::Cow;
use std::collections::BTreeMap;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::mpsc::{Receiver, SyncSender, sync_channel};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, SystemTime};

/// Image file format of captured frames.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FrameFormat {
    Png,
    Pgm,
}

impl FrameFormat {
    /// Parses `png` or `pgm`.
    pub fn parse(s: &str) -> Result<Self, String> {
        match s.to_ascii_lowercase().as_str() {
            "png" => Ok(FrameFormat::Png),
            "pgm" => Ok(FrameFormat::Pgm),
            _ => Err(format!("unknown frame format {s:?} (expected png or pgm)")),
        }
    }

    /// The file extension, without the dot.
    pub fn extension(self) -> &'static str {
        match self {
            FrameFormat::Png => "png",
            FrameFormat::Pgm => "pgm",
        }
    }

    /// The file name of a frame with this stem, e.g. `000012` → `000012.pgm`.
    pub fn file_name(self, stem: &str) -> String {
        format!("{stem}.{}", self.extension())
    }
}

/// One grey camera image as it came off the wire.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RawFrame {
    pub width: u32,
    pub height: u32,
    /// 8 or 16.
    pub bit_depth: u8,
    /// Row-major samples; 16-bit samples little-endian (GenICam `Mono16`).
    pub data: Vec<u8>,
}

impl RawFrame {
    /// Checks that the data holds exactly `width × height` samples.
    pub fn check(&self) -> Result<(), String> {
        let bytes = if self.bit_depth == 16 { 2 } else { 1 };
        let want = self.width as usize * self.height as usize * bytes;
        if !matches!(self.bit_depth, 8 | 16) {
            return Err(format!("unsupported bit depth {}", self.bit_depth));
        }
        if self.data.len() < want {
            return Err(format!(
                "{} bytes for a {}x{} {}-bit image (needs {want})",
                self.data.len(),
                self.width,
                self.height,
                self.bit_depth
            ));
        }
        Ok(())
    }
}

/// The file contents of `frame` in `format`.
pub fn encode(frame: &RawFrame, format: FrameFormat) -> std::io::Result<Vec<u8>> {
    let (mut head, body) = encode_parts(frame, format)?;
    head.extend_from_slice(&body);
    Ok(head)
}

/// The file contents of `frame` in `format` as a head and a body to write after it: an 8-bit
/// PGM's body is the camera's own samples, written without a copy.
fn encode_parts(frame: &RawFrame, format: FrameFormat) -> std::io::Result<(Vec<u8>, Cow<'_, [u8]>)> {
    frame.check().map_err(std::io::Error::other)?;
    let n = frame.width as usize * frame.height as usize;
    match format {
        FrameFormat::Pgm => {
            let max = if frame.bit_depth == 16 { 65535 } else { 255 };
            let head = format!("P5\n{} {}\n{max}\n", frame.width, frame.height).into_bytes();
            let body = if frame.bit_depth == 16 {
                // Little-endian samples to PGM's big-endian ones (a loop the compiler vectorises).
                let mut be = vec![0u8; 2 * n];
                for (d, s) in be.chunks_exact_mut(2).zip(frame.data[..2 * n].chunks_exact(2)) {
                    d[0] = s[1];
                    d[1] = s[0];
                }
                Cow::Owned(be)
            } else {
                Cow::Borrowed(&frame.data[..n])
            };
            Ok((head, body))
        }
        FrameFormat::Png => {
            let mut buf = Vec::new();
            let (bytes, color) = if frame.bit_depth == 16 {
                let ne: Vec<u8> = frame.data[..2 * n]
                    .chunks_exact(2)
                    .flat_map(|s| u16::from_le_bytes([s[0], s[1]]).to_ne_bytes())
                    .collect();
                (Cow::Owned(ne), image::ExtendedColorType::L16)
            } else {
                (Cow::Borrowed(&frame.data[..n]), image::ExtendedColorType::L8)
            };
            omni_formats::png::write_png(&mut buf, &bytes, frame.width, frame.height, color)
                .map_err(std::io::Error::other)?;
            Ok((buf, Cow::Borrowed(&[])))
        }
    }
}

/// Writes `frame` to `path` in `format` atomically, with modification time `exposure`, synced
/// to disk before the rename if `sync`.
fn write_frame(
    path: &Path,
    frame: &RawFrame,
    format: FrameFormat,
    exposure: SystemTime,
    sync: bool,
) -> std::io::Result<()> {
    let (head, body) = encode_parts(frame, format)?;
    let mut tmp = omni_formats::io::TempFile::create(path)?;
    tmp.file().write_all(&head)?;
    tmp.file().write_all(&body)?;
    tmp.file().set_modified(exposure)?;
    if sync { tmp.commit() } else { tmp.commit_unsynced() }
}

struct Job {
    order: u64,
    frame: CapturedFrame,
    image: RawFrame,
    sync: bool,
}

type Done = (u64, std::io::Result<CapturedFrame>);

/// Writes frames on worker threads and hands them back in the order they were submitted, so
/// the pairing sees frames in capture order. The queue is bounded: [`FrameWriter::submit`]
/// blocks while `queue` frames wait, which bounds memory (the camera's own buffers then fill,
/// and the stream reports the frames it had to drop).
pub struct FrameWriter {
    dir: PathBuf,
    format: FrameFormat,
    sync: bool,
    jobs: Option<SyncSender<Job>>,
    done: Receiver<Done>,
    workers: Vec<JoinHandle<()>>,
    submitted: u64,
    next_out: u64,
    finished: BTreeMap<u64, std::io::Result<CapturedFrame>>,
}

impl FrameWriter {
    /// Writes into `dir` (created if missing) with `threads` workers and up to `queue` frames
    /// waiting.
    pub fn new(dir: &Path, format: FrameFormat, threads: usize, queue: usize) -> std::io::Result<Self> {
        std::fs::create_dir_all(dir)?;
        let (jobs, rx) = sync_channel::<Job>(queue.max(1));
        let rx = Arc::new(Mutex::new(rx));
        let (done_tx, done) = std::sync::mpsc::channel::<Done>();
        let workers = (0..threads.max(1))
            .map(|_| {
                let (rx, done_tx) = (rx.clone(), done_tx.clone());
                std::thread::spawn(move || work(&rx, &done_tx, format))
            })
            .collect();
        Ok(FrameWriter {
            dir: dir.to_path_buf(),
            format,
            sync: false,
            jobs: Some(jobs),
            done,
            workers,
            submitted: 0,
            next_out: 0,
            finished: BTreeMap::new(),
        })
    }

    /// Syncs each frame submitted from now on to disk before renaming it into place, so that a
    /// power cut loses none of them once handed back.
    pub fn sync_each_frame(&mut self, sync: bool) {
        self.sync = sync;
    }

    /// The file name of a frame with this stem, e.g. `000012` → `000012.pgm`.
    pub fn file_name(&self, stem: &str) -> String {
        self.format.file_name(stem)
    }

    /// Queues `image` to be written as `frame.name` in the directory; `frame` (its `path` set
    /// here) comes back from [`FrameWriter::written`] once the file is complete.
    pub fn submit(&mut self, mut frame: CapturedFrame, image: RawFrame) -> std::io::Result<()> {
        frame.path = self.dir.join(&frame.name);
        let job = Job { order: self.submitted, frame, image, sync: self.sync };
        let jobs = self.jobs.as_ref().ok_or_else(|| std::io::Error::other("frame writer closed"))?;
        jobs.send(job).map_err(|_| std::io::Error::other("frame writer threads stopped"))?;
        self.submitted += 1;
        Ok(())
    }

    /// Frames written since the previous call, in submission order; the first write error
    /// ends the list.
    pub fn written(&mut self) -> std::io::Result<Vec<CapturedFrame>> {
        while let Ok((order, result)) = self.done.try_recv() {
            self.finished.insert(order, result);
        }
        self.take_in_order()
    }

    /// Waits up to `timeout` for every submitted frame, then returns them like
    /// [`FrameWriter::written`].
    pub fn flush(&mut self, timeout: Duration) -> std::io::Result<Vec<CapturedFrame>> {
        let deadline = std::time::Instant::now() + timeout;
        while self.next_out + (self.finished.len() as u64) < self.submitted {
            let left = deadline.saturating_duration_since(std::time::Instant::now());
            match self.done.recv_timeout(left) {
                Ok((order, result)) => {
                    self.finished.insert(order, result);
                }
                Err(_) => break,
            }
        }
        self.take_in_order()
    }

    fn take_in_order(&mut self) -> std::io::Result<Vec<CapturedFrame>> {
        let mut out = Vec::new();
        while let Some(result) = self.finished.remove(&self.next_out) {
            self.next_out += 1;
            out.push(result?);
        }
        Ok(out)
    }
}

impl Drop for FrameWriter {
    fn drop(&mut self) {
        self.jobs.take();
        for w in self.workers.drain(..) {
            let _ = w.join();
        }
    }
}

fn work(jobs: &Mutex<Receiver<Job>>, done: &std::sync::mpsc::Sender<Done>, format: FrameFormat) {
    loop {
        let job = {
            let Ok(rx) = jobs.lock() else { return };
            match rx.recv() {
                Ok(j) => j,
                Err(_) => return,
            }
        };
        let exposure = SystemTime::UNIX_EPOCH + Duration::from_micros(job.frame.time_us.max(0) as u64);
        let name = job.frame.path.display().to_string();
        let result = write_frame(&job.frame.path, &job.image, format, exposure, job.sync)
            .map(|_| job.frame)
            .map_err(|e| std::io::Error::new(e.kind(), format!("{name}: {e}")));
        if done.send((job.order, result)).is_err() {
            return;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ramp(width: u32, height: u32, bit_depth: u8, shift: u32) -> RawFrame {
        let n = (width * height) as usize;
        let data = if bit_depth == 16 {
            (0..n).flat_map(|i| ((i as u32 * 257 + shift) as u16).to_le_bytes()).collect()
        } else {
            (0..n).map(|i| ((i as u32 + shift) % 256) as u8).collect()
        };
        RawFrame { width, height, bit_depth, data }
    }

    /// The PGM layout (netpbm's `pgm(5)`): `P5`, width, height, maxval as decimal text
    /// separated by whitespace, one whitespace byte, then samples, 2 bytes big-endian when
    /// maxval > 255.
    #[test]
    fn pgm_files_follow_the_netpbm_layout() {
        let f = ramp(3, 2, 16, 1);
        let bytes = encode(&f, FrameFormat::Pgm).unwrap();
        let header = b"P5\n3 2\n65535\n";
        assert_eq!(&bytes[..header.len()], header);
        let samples: Vec<u16> =
            bytes[header.len()..].chunks_exact(2).map(|s| u16::from_be_bytes([s[0], s[1]])).collect();
        assert_eq!(samples, (0..6).map(|i| (i * 257 + 1) as u16).collect::<Vec<_>>());
        let f8 = ramp(4, 1, 8, 250);
        assert_eq!(encode(&f8, FrameFormat::Pgm).unwrap(), b"P5\n4 1\n255\n\xfa\xfb\xfc\xfd");
    }

    /// Synced or not, 8- or 16-bit, a frame file holds exactly its encoding (checked against
    /// the netpbm layout above), and no temporary is left.
    #[test]
    fn synced_and_unsynced_frames_are_the_same_files() {
        let dir = tempfile::tempdir().unwrap();
        let mut w = FrameWriter::new(dir.path(), FrameFormat::Pgm, 2, 4).unwrap();
        let frame = |k: u32| ramp(16, 4, if k < 2 { 8 } else { 16 }, k);
        for k in 0..4u32 {
            w.sync_each_frame(k % 2 == 1);
            let name = w.file_name(&format!("{k:06}"));
            w.submit(CapturedFrame::new(PathBuf::new(), name, 0), frame(k)).unwrap();
        }
        let got = w.flush(Duration::from_secs(20)).unwrap();
        assert_eq!(got.len(), 4);
        for (k, f) in got.iter().enumerate() {
            assert_eq!(std::fs::read(&f.path).unwrap(), encode(&frame(k as u32), FrameFormat::Pgm).unwrap());
        }
        let last = std::fs::read(&got[3].path).unwrap();
        assert_eq!(last.len(), b"P5\n16 4\n65535\n".len() + 2 * 64);
        assert_eq!(&last[last.len() - 2..], ((63 * 257 + 3) as u16).to_be_bytes(), "big-endian samples");
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 4, "no temporary file left");
    }

    #[test]
    fn short_data_is_refused() {
        let mut f = ramp(4, 4, 8, 0);
        f.data.pop();
        let e = encode(&f, FrameFormat::Pgm).unwrap_err().to_string();
        assert!(e.contains("15 bytes for a 4x4 8-bit image"), "{e}");
    }

    #[test]
    fn frames_come_back_in_submission_order_with_their_exposure_time() {
        let dir = tempfile::tempdir().unwrap();
        let mut w = FrameWriter::new(dir.path(), FrameFormat::Png, 3, 2).unwrap();
        let t0 = 1_700_000_000_000_000;
        for k in 0..12u32 {
            let name = w.file_name(&format!("{k:06}"));
            // Big and small frames alternate so that the workers finish out of order.
            let side = if k % 2 == 0 { 256 } else { 8 };
            w.submit(CapturedFrame::new(PathBuf::new(), name, t0 + k as i64 * 1000), ramp(side, side, 8, k)).unwrap();
        }
        let got = w.flush(Duration::from_secs(20)).unwrap();
        let names: Vec<String> = got.iter().map(|f| f.name.clone()).collect();
        assert_eq!(names, (0..12).map(|k| format!("{k:06}.png")).collect::<Vec<_>>());
        let meta = std::fs::metadata(&got[5].path).unwrap();
        let mtime = meta.modified().unwrap().duration_since(SystemTime::UNIX_EPOCH).unwrap().as_micros() as i64;
        assert_eq!(mtime, t0 + 5000);
        assert!(w.written().unwrap().is_empty());
        let hidden = std::fs::read_dir(dir.path())
            .unwrap()
            .filter(|e| e.as_ref().unwrap().file_name().to_string_lossy().starts_with('.'));
        assert_eq!(hidden.count(), 0, "no temporary file left");
    }
}
