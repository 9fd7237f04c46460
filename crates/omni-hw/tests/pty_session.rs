//! The library API end to end, in one process: the emulator serving a real pseudo-terminal on a
//! thread, the host opening it through `serialport` like a USB controller, and a scan through a
//! custom [`FrameSource`] (here wrapping the directory source, as a camera SDK source would).

use omni_hw::emulator::{BlankRenderer, EmulatorOptions, Faults, ServeEnd, VirtualCamera, read_truth, serve};
use omni_hw::pairing::{CapturedFrame, DirFrameSource, FrameSource, PairEvent};
use omni_hw::scan::{ScanConfig, configure, run_scan};
use omni_hw::schedule::AngleSpec;
use omni_hw::{Client, ClientOptions};
use std::time::Duration;

/// A frame source that counts how often it is asked: pairing sees only the trait.
struct Counting {
    inner: DirFrameSource,
    polls: u64,
}

impl FrameSource for Counting {
    fn poll(&mut self) -> std::io::Result<Vec<CapturedFrame>> {
        self.polls += 1;
        self.inner.poll()
    }
    fn describe(&self) -> String {
        self.inner.describe()
    }
}

#[test]
fn library_scan_over_a_pseudo_terminal_with_corrupted_lines() {
    let dir = tempfile::tempdir().unwrap();
    let frames = dir.path().join("frames");
    let truth = dir.path().join("truth.jsonl");
    let (mut master, slave) = serialport::TTYPort::pair().unwrap();
    let path = serialport::SerialPort::name(&slave).unwrap();
    drop(slave);
    serialport::SerialPort::set_timeout(&mut master, Duration::from_millis(2)).unwrap();
    let mut camera = VirtualCamera::start(
        &frames,
        Box::new(BlankRenderer { width: 8, height: 8 }),
        Duration::ZERO,
        Some(truth.clone()),
    )
    .unwrap();
    let mut options = EmulatorOptions::default();
    // 10 Hz: the frames pair within ±0.4 trigger gaps (±40 ms), which a loaded machine's
    // thread scheduling keeps to (at 40 Hz, ±10 ms, CI once saw a frame arrive late).
    options.spec.max_rate_hz = 10.0;
    options.faults = Faults { bad_crc: 0.1, seed: 11, ..Faults::default() };
    let emulator = std::thread::spawn(move || {
        let end = serve(&mut master, &options, &mut camera);
        camera.finish();
        end
    });

    let port = serialport::new(&path, 115_200).timeout(Duration::from_millis(20)).open_native().unwrap();
    let mut client = Client::new(port, ClientOptions::default());
    let info = client.hello().unwrap();
    assert_eq!((info.counts_per_rev, info.facets, info.lasers), (36000, 12, 2));
    let cfg = ScanConfig::new(AngleSpec::parse("0,15").unwrap(), 1);
    let (schedule, rpm) = configure(&mut client, &info, &cfg).unwrap();
    // 24 triggers per revolution at 10 Hz, evenly spaced: 2.4 s per revolution.
    assert!((rpm - 25.0).abs() < 1e-9, "{rpm}");
    let mut source = Counting { inner: DirFrameSource::new(&frames).unwrap(), polls: 0 };
    let mut records = Vec::new();
    let mut sink = |e: &PairEvent| {
        if let PairEvent::Paired(f) = e {
            records.push((**f).clone());
        }
        Ok(())
    };
    let source_dyn: &mut dyn FrameSource = &mut source;
    let outcome = run_scan(&mut client, source_dyn, schedule, rpm, &cfg, &mut sink);
    drop(client);
    assert_eq!(emulator.join().unwrap().unwrap(), ServeEnd::HostDisconnected);

    assert!(outcome.error.is_none(), "{outcome:?}");
    assert!(source.polls > 10);
    assert_eq!((outcome.status.frames, outcome.status.frames_missing), (24, 0), "{:?}", outcome.status);
    let truth = read_truth(&truth).unwrap();
    for f in &records {
        let t = truth.iter().find(|t| t.path == f.path).unwrap();
        assert_eq!((t.trigger_seq, t.facet), (f.seq, f.facet));
        assert!((t.alpha_deg - f.alpha_deg).abs() < 1e-9);
    }
}
