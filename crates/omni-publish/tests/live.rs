//! The live loop on streams written into a pipe as a scan would: sweeps out as they close, a
//! slow output loses its oldest sweeps without holding back the input, a stalled input gives
//! an incomplete sweep after the timeout, frames are deleted once measured.

use omni_formats::stream::{Frame, Header, Point, Record, Status, StreamReader, StreamWriter, StripePoint};
use omni_publish::live::{self, FrameRetention, LIVE_HEADER_FIELD, LiveOptions, Published};
use omni_publish::{FrameFile, Sink, Sweep};
use std::io::{BufReader, Write};
use std::sync::atomic::AtomicBool;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// A frame of sweep `k` (facet k mod 12), `n` points, 5 ms after the previous one.
fn frame(seq: u64, k: u64, path: String, n: usize) -> Frame {
    let mut f = Frame::new(seq, path, 14.0 + (seq % 5) as f64, (k % 12) as u32);
    f.revolution = k / 12;
    f.timestamp_us = Some(1_000_000 + 5_000 * seq);
    f.lasers = vec![0];
    f.stripe = Some(vec![StripePoint { u: 1.0, v: 2.0, intensity: 90.0, width: 2.5, quality: 0 }; n]);
    f.points = Some(
        (0..n)
            .map(|i| Point { xyz: [seq as f64, i as f64, 500.0], laser: 0, range: 500.0, stripe_index: i as u32 })
            .collect(),
    );
    f
}

fn line(record: &Record) -> Vec<u8> {
    let mut buf = Vec::new();
    StreamWriter::new(&mut buf, "test").write(record).unwrap();
    buf
}

fn header(angles: Option<&str>, frames_dir: Option<&str>) -> Record {
    let mut h = Header::new("test");
    h.frames_dir = frames_dir.map(String::from);
    if let Some(a) = angles {
        h.extra.insert("angles".into(), a.into());
    }
    Record::Header(h)
}

/// What an output got of a sweep: revolution, facet, points, complete.
type Got = (u64, u32, usize, bool);

/// An output that takes `delay` per sweep and remembers what it got.
struct SlowSink {
    delay: Duration,
    got: Arc<Mutex<Vec<Got>>>,
}

impl Sink for SlowSink {
    fn name(&self) -> &str {
        "slow"
    }
    fn publish(&mut self, s: &Sweep, _frame: Option<&FrameFile>) -> Result<(), String> {
        std::thread::sleep(self.delay);
        self.got.lock().unwrap().push((s.revolution, s.facet, s.points.len(), s.complete));
        Ok(())
    }
}

type Reports = Arc<Mutex<Vec<Published>>>;

fn run_on_pipe(
    opts: LiveOptions,
    delay: Duration,
    write: impl FnOnce(&mut std::io::PipeWriter) + Send + 'static,
) -> (live::Summary, Vec<Got>, Vec<Published>) {
    let (reader, mut writer) = std::io::pipe().unwrap();
    let feeder = std::thread::spawn(move || write(&mut writer));
    let got = Arc::new(Mutex::new(Vec::new()));
    let reports: Reports = Arc::default();
    let r2 = reports.clone();
    let summary = live::run(
        StreamReader::new(BufReader::new(reader), "pipe"),
        vec![Box::new(SlowSink { delay, got: got.clone() })],
        Arc::new(move |p| r2.lock().unwrap().push(p)),
        &opts,
        None,
        Arc::new(AtomicBool::new(false)),
    )
    .unwrap();
    feeder.join().unwrap();
    let got = got.lock().unwrap().clone();
    let reports = reports.lock().unwrap().clone();
    (summary, got, reports)
}

fn options() -> LiveOptions {
    LiveOptions {
        sweep_timeout: Duration::from_millis(150),
        queue: 2,
        frames_per_sweep: None,
        frames: FrameRetention::Keep,
    }
}

#[test]
fn sweeps_close_on_their_last_frame_as_the_header_angles_tell() {
    // A queue long enough for the whole burst: here every sweep must arrive.
    let opts = LiveOptions { queue: 8, ..options() };
    let (summary, got, reports) = run_on_pipe(opts, Duration::ZERO, |w| {
        w.write_all(&line(&header(Some("14:19:1"), None))).unwrap();
        for seq in 0..15 {
            w.write_all(&line(&Record::Frame(Box::new(frame(seq, seq / 5, format!("{seq}.png"), 3))))).unwrap();
        }
        w.write_all(&line(&Record::Status(Status::complete(15)))).unwrap();
    });
    assert_eq!(got, vec![(0, 0, 15, true), (0, 1, 15, true), (0, 2, 15, true)]);
    assert_eq!((summary.sweeps, summary.sweeps_incomplete, summary.frames), (3, 0, 15));
    assert!(!summary.cut_short && summary.input_status.is_some_and(|s| s.complete));
    assert!(reports.iter().all(|p| p.sink == "slow" && p.error.is_none()), "{reports:?}");
}

#[test]
fn a_slow_output_loses_its_oldest_sweeps_and_never_holds_back_the_input() {
    // 40 sweeps arrive at once; the output needs 40 ms for each.
    let start = Instant::now();
    let (summary, got, _) = run_on_pipe(options(), Duration::from_millis(40), |w| {
        w.write_all(&line(&header(Some("14:19:1"), None))).unwrap();
        for seq in 0..200 {
            w.write_all(&line(&Record::Frame(Box::new(frame(seq, seq / 5, format!("{seq}.png"), 2))))).unwrap();
        }
        w.write_all(&line(&Record::Status(Status::complete(200)))).unwrap();
    });
    let dropped = summary.dropped["slow"];
    assert_eq!(summary.sweeps, 40);
    assert_eq!(got.len() as u64 + dropped, 40, "every sweep either published or counted as dropped");
    assert!(dropped >= 30, "only {dropped} dropped: the input waited for the output");
    // The newest sweeps are the ones kept.
    assert_eq!(got.last().map(|g| (g.0, g.1)), Some((3, 3)), "{got:?}");
    assert!(start.elapsed() < Duration::from_secs(5), "{:?}", start.elapsed());
}

#[test]
fn a_sweep_whose_frames_stop_arriving_is_published_incomplete_after_the_timeout() {
    let (summary, got, reports) = run_on_pipe(options(), Duration::ZERO, |w| {
        w.write_all(&line(&header(Some("14:19:1"), None))).unwrap();
        for seq in 0..3 {
            w.write_all(&line(&Record::Frame(Box::new(frame(seq, 0, format!("{seq}.png"), 2))))).unwrap();
        }
        w.flush().unwrap();
        // The camera stops for longer than the timeout, then the next sweep comes.
        std::thread::sleep(Duration::from_millis(600));
        for seq in 5..10 {
            w.write_all(&line(&Record::Frame(Box::new(frame(seq, 1, format!("{seq}.png"), 2))))).unwrap();
        }
    });
    assert_eq!(got, vec![(0, 0, 6, false), (0, 1, 10, true)]);
    assert_eq!(summary.sweeps_incomplete, 1);
    assert!(summary.cut_short, "no status record");
    // Published on the timeout, not when the next sweep came 600 ms later.
    let first = &reports[0];
    assert!(first.latency_ms >= 140.0 && first.latency_ms < 450.0, "{}", first.latency_ms);
}

#[test]
fn frames_are_deleted_once_measured_and_laser_off_frames_once_no_frame_can_need_them() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path().to_path_buf();
    let names: Vec<String> = (0..30).map(|i| format!("f{i}.pgm")).collect();
    for n in &names {
        std::fs::write(d.join(n), b"P5 1 1 255 x").unwrap();
    }
    let opts = LiveOptions { frames: FrameRetention::Delete, frames_per_sweep: Some(5), ..options() };
    let dir_name = d.display().to_string();
    let check_dir = d.clone();
    let (summary, _, _) = run_on_pipe(opts, Duration::ZERO, move |w| {
        w.write_all(&line(&header(None, Some(&dir_name)))).unwrap();
        // Revolution 0 laser-off (lasers []), revolutions 1 and 2 with the laser, 10 frames each
        // (2 facets of 5).
        for seq in 0..30u64 {
            let rev = seq / 10;
            let mut f = frame(seq, rev * 12 + (seq % 10) / 5, format!("f{seq}.pgm"), 1);
            if rev == 0 {
                f.lasers = vec![];
                f.points = Some(vec![]);
            } else {
                f.ambient_path = Some(format!("f{}.pgm", seq % 10));
            }
            w.write_all(&line(&Record::Frame(Box::new(f)))).unwrap();
            w.flush().unwrap();
            if seq == 19 {
                // After revolution 1: its laser frames are gone, revolution 0's laser-off
                // frames stay (revolution 1 may still be in flight upstream).
                std::thread::sleep(Duration::from_millis(100));
                // The latest laser frame waits for the next one (the image of the sweep it closes).
                let left: Vec<bool> = (0..20).map(|i| check_dir.join(format!("f{i}.pgm")).exists()).collect();
                assert!(left[..10].iter().all(|&x| x), "laser-off frames deleted too early: {left:?}");
                assert!(left[10..19].iter().all(|&x| !x), "laser frames kept: {left:?}");
                assert!(left[19], "the latest laser frame deleted before the next arrived");
            }
        }
        w.write_all(&line(&Record::Status(Status::complete(30)))).unwrap();
    });
    assert_eq!(summary.frames_deleted, 30);
    assert_eq!(std::fs::read_dir(&d).unwrap().count(), 0);
}

/// Frames left after a five-frame stream whose header does or does not mark a live capture.
fn frames_left_after(live_header: bool, frames: FrameRetention) -> usize {
    let dir = tempfile::tempdir().unwrap();
    for i in 0..5 {
        std::fs::write(dir.path().join(format!("f{i}.pgm")), b"P5 1 1 255 x").unwrap();
    }
    let mut h = header(None, Some(&dir.path().display().to_string()));
    if let Record::Header(h) = &mut h {
        h.extra.insert(LIVE_HEADER_FIELD.into(), live_header.into());
    }
    let opts = LiveOptions { frames, frames_per_sweep: Some(5), ..options() };
    let (summary, _, _) = run_on_pipe(opts, Duration::ZERO, move |w| {
        w.write_all(&line(&h)).unwrap();
        for seq in 0..5u64 {
            w.write_all(&line(&Record::Frame(Box::new(frame(seq, 0, format!("f{seq}.pgm"), 1))))).unwrap();
        }
        w.write_all(&line(&Record::Status(Status::complete(5)))).unwrap();
    });
    let left = std::fs::read_dir(dir.path()).unwrap().count();
    assert_eq!(summary.frames_deleted as usize, 5 - left);
    left
}

#[test]
fn a_live_capture_loses_its_frames_once_measured_and_a_recorded_scan_keeps_them() {
    assert_eq!(frames_left_after(true, FrameRetention::AsStreamSays), 0);
    assert_eq!(frames_left_after(false, FrameRetention::AsStreamSays), 5);
    assert_eq!(frames_left_after(true, FrameRetention::Keep), 5);
    assert_eq!(frames_left_after(false, FrameRetention::Delete), 0);
}
