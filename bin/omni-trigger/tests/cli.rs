//! End-to-end tests: the real `omni-trigger` binary scanning against `omni-trigger emulate` on a
//! real pseudo-terminal (the production path through `serialport`), clean and with each fault.
//! Ground truth: the emulator's `--truth` file says which trigger and true angle each frame shows.

mod common;

use common::*;
use omni_formats::stream::{Frame, Status};
use std::collections::HashMap;
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// 24 triggers per revolution (angles 0° and 15° on all 12 facets), evenly spaced.
const FAST: [&str; 4] = ["--angles", "0,15", "--revolutions", "1"];

#[test]
fn clean_scan_of_two_revolutions_gives_exactly_the_expected_manifest() {
    // A camera with a frame buffer: a clean scan must not depend on the machine's load. Unbuffered,
    // a 200 ms stall while the tests beside it link (seen in CI) made the camera miss 4 triggers
    // at 20 Hz; missed triggers have tests of their own.
    let emu = Emulator::start(&["--camera-mode", "blank", "--max-rate-hz", "20", "--buffered-camera"]);
    let out = emu.scan(&["--angles", "0,15", "--revolutions", "2"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let (frames, status) = read_manifest(&emu.manifest_path());
    assert_eq!(frames.len(), 48);
    for (i, f) in frames.iter().enumerate() {
        let i = i as u64;
        let (rev, facet, alpha) = (i / 24, (i % 24 / 2) as u32, if i.is_multiple_of(2) { 0.0 } else { 15.0 });
        assert_eq!(f.seq, i);
        assert_eq!(f.path, format!("frame_{i:06}.png"));
        assert_eq!((f.facet, f.revolution, f.alpha_deg), (facet, rev, alpha), "frame {i}");
        assert_eq!(f.encoder, Some(facet as u64 * 3000 + if i.is_multiple_of(2) { 0 } else { 1500 }));
        assert_eq!(f.lasers, vec![0, 1]);
        assert!(f.ambient_path.is_none());
    }
    let t: Vec<u64> = frames.iter().map(|f| f.timestamp_us.unwrap()).collect();
    assert!(t.windows(2).all(|w| w[1] - w[0] == 50_000), "20 Hz, evenly spaced: {t:?}");
    assert_frames_true(&frames, &emu.truth());
    assert_eq!((status.frames, status.frames_missing, status.complete), (48, 0, true));
    assert!(status.errors.is_empty(), "{:?}", status.errors);
    assert_eq!(extra(&status, "controller_fired"), 48);
}

#[test]
fn rendered_frames_through_the_simulator_pair_with_their_true_angles_and_ambient_frames() {
    let emu = Emulator::start(&["--width", "64"]);
    let out = emu.scan(&[
        "--angles",
        "5,20",
        "--facets",
        "0,3,6,9",
        "--revolutions",
        "1",
        "--laser-off",
        "--max-missing",
        "4",
    ]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let (frames, status) = read_manifest(&emu.manifest_path());
    assert_frames_true(&frames, &emu.truth());
    // Rendering speed varies with machine load: a missed frame is allowed, but accounted for.
    assert_eq!(status.frames + status.frames_missing, 16, "{status:?}");
    assert!(status.frames >= 12, "{status:?}");
    let paths: HashMap<u64, &Frame> = frames.iter().map(|f| (f.seq, f)).collect();
    for f in &frames {
        let png = std::fs::read(emu.frames().join(&f.path)).unwrap();
        assert_eq!(&png[1..4], b"PNG");
        let (w, h) =
            (u32::from_be_bytes(png[16..20].try_into().unwrap()), u32::from_be_bytes(png[20..24].try_into().unwrap()));
        assert_eq!((w, h), (64, 64));
        if f.revolution == 0 {
            assert!(f.lasers.is_empty(), "revolution 0 is the laser-off revolution");
        } else {
            assert_eq!(f.lasers, vec![0, 1]);
            // Its ambient frame: same encoder count one revolution (8 triggers) earlier, if paired.
            let expected = paths.get(&(f.seq - 8)).map(|a| a.path.clone());
            assert_eq!(f.ambient_path, expected, "frame {}", f.seq);
        }
    }
    // A laser frame differs from its ambient frame: the stripe is drawn.
    let laser = frames.iter().find(|f| f.ambient_path.is_some()).expect("some laser frame with its ambient frame");
    let a = std::fs::read(emu.frames().join(&laser.path)).unwrap();
    let b = std::fs::read(emu.frames().join(laser.ambient_path.as_ref().unwrap())).unwrap();
    assert_ne!(a, b);
}

/// Runs a 24-trigger scan against an emulator with `fault` and checks what must hold whatever
/// was lost: exit 0, a valid manifest, true angles, every frame the camera wrote paired (the
/// camera itself may miss triggers on a loaded machine), every trigger accounted for.
fn faulty_scan(fault: &[&str]) -> (Vec<Frame>, Status) {
    let mut args = vec!["--camera-mode", "blank", "--max-rate-hz", "40"];
    args.extend_from_slice(fault);
    let emu = Emulator::start(&args);
    let mut scan_args = FAST.to_vec();
    scan_args.extend(["--max-missing", "24"]);
    let out = emu.scan(&scan_args);
    assert!(out.status.success(), "{fault:?}: {}", String::from_utf8_lossy(&out.stderr));
    let (frames, status) = read_manifest(&emu.manifest_path());
    eprintln!("{fault:?}: {} paired, {} missing, extra {:?}", status.frames, status.frames_missing, status.extra);
    assert_frames_true(&frames, &emu.truth());
    assert!(status.complete, "{status:?}");
    assert_eq!(status.frames + status.frames_missing, 24, "every trigger is paired or reported: {status:?}");
    let written = emu.truth().len();
    assert_eq!((frames.len(), extra(&status, "frames_unmatched")), (written, 0), "every frame pairs: {status:?}");
    if status.frames_missing > 0 {
        assert!(!status.errors.is_empty(), "losses must be explained: {status:?}");
        assert!(!out.stderr.is_empty(), "losses must be warned about");
    }
    (frames, status)
}

#[test]
fn bad_checksums_are_dropped_commands_retried_and_lost_events_reported() {
    let (frames, status) = faulty_scan(&["--bad-crc", "0.25", "--fault-seed", "3"]);
    assert!(extra(&status, "line_crc_errors") > 0, "{status:?}");
    // The fault generator is seeded: with seed 3 some ACKs of the configuration are corrupted,
    // and the configuration still completes through retries with the same ids.
    assert!(extra(&status, "command_retries") > 0, "{status:?}");
    assert_recovered(&frames, &status);
}

/// Lost events were placed from the schedule and every frame still paired with its own trigger.
fn assert_recovered(frames: &[Frame], status: &Status) {
    let lost = extra(status, "events_lost");
    assert!(lost > 0, "the fault should have cost some events: {status:?}");
    let inferred =
        frames.iter().filter(|f| f.extra.get("trigger_inferred") == Some(&serde_json::Value::Bool(true))).count()
            as u64;
    // A lost event's frame is still paired (unless the camera missed that trigger too).
    assert!(inferred > 0 && inferred <= lost, "{status:?}");
    assert_eq!(extra(status, "frames_with_inferred_trigger"), inferred);
}

#[test]
fn garbage_between_lines_is_survived() {
    let (frames, status) = faulty_scan(&["--garbage", "0.4", "--fault-seed", "5"]);
    assert!(extra(&status, "line_crc_errors") + extra(&status, "lines_malformed") > 0, "{status:?}");
    assert_recovered(&frames, &status);
}

#[test]
fn dropped_events_are_placed_from_the_schedule_and_their_frames_kept() {
    let (frames, status) = faulty_scan(&["--drop-events", "0.2", "--fault-seed", "7"]);
    assert_recovered(&frames, &status);
}

#[test]
fn duplicated_events_are_counted_once() {
    let (frames, status) = faulty_scan(&["--dup-events", "0.3", "--fault-seed", "9"]);
    assert!(extra(&status, "events_duplicated") > 0);
    assert_eq!(frames.len() as u64, extra(&status, "triggers") - status.frames_missing, "{status:?}");
}

#[test]
fn a_slow_camera_misses_frames_and_they_are_reported_missing() {
    // 40 Hz = 25 ms per trigger; 40 ms per frame: the camera misses about every other trigger.
    let (frames, status) = faulty_scan(&["--slow-camera-ms", "40"]);
    // Nominally 12 and 12; a loaded machine makes the camera slower still, never faster.
    assert!(status.frames_missing >= 8, "{status:?}");
    assert!(frames.len() >= 4, "{status:?}");
    assert_eq!(extra(&status, "frames_unmatched"), 0);
}

#[test]
fn a_disconnect_mid_scan_stops_with_an_error_and_keeps_the_partial_manifest() {
    let mut emu = Emulator::start(&["--camera-mode", "blank", "--max-rate-hz", "40", "--disconnect-after", "7"]);
    let out = emu.scan(&FAST);
    assert_eq!(out.status.code(), Some(1));
    let stderr = String::from_utf8_lossy(&out.stderr);
    let last = stderr.lines().last().unwrap_or_default();
    assert!(last.starts_with("omni-trigger: error:") && last.contains("hung up"), "{stderr}");
    let (frames, status) = read_manifest(&emu.manifest_path());
    assert!(!status.complete);
    assert!(status.errors.iter().any(|e| e.contains("disconnected")), "{status:?}");
    assert!(frames.len() <= 7);
    assert_frames_true(&frames, &emu.truth());
    // The emulator ends by itself after its unplug, its last frame finished, none half-written.
    let t0 = std::time::Instant::now();
    while emu.child.try_wait().unwrap().is_none() {
        assert!(t0.elapsed() < std::time::Duration::from_secs(10), "the emulator did not end");
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    let temps: Vec<_> = std::fs::read_dir(emu.frames())
        .unwrap()
        .filter_map(|e| e.ok().map(|e| e.file_name().to_string_lossy().into_owned()))
        .filter(|n| n.contains("omniscan-tmp"))
        .collect();
    assert!(temps.is_empty(), "{temps:?}");
}

#[test]
fn an_unplugged_port_ends_the_scan_within_one_second() {
    let mut emu = Emulator::start(&["--camera-mode", "blank", "--max-rate-hz", "40"]);
    let mut scan = Command::new(BIN)
        .args(["scan", "--port", &emu.port, "--angles", "0,15", "--revolutions", "20", "--frames"])
        .arg(emu.frames())
        .arg("-o")
        .arg(emu.manifest_path())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let started = Instant::now();
    while std::fs::read_to_string(emu.manifest_path()).map(|t| t.matches("\"frame\"").count()).unwrap_or(0) < 5 {
        assert!(started.elapsed() < Duration::from_secs(10), "scan produced no frames");
        std::thread::sleep(Duration::from_millis(10));
    }
    let unplugged = Instant::now();
    emu.child.kill().unwrap();
    emu.child.wait().unwrap();
    let status = loop {
        if let Some(s) = scan.try_wait().unwrap() {
            break s;
        }
        assert!(unplugged.elapsed() < Duration::from_secs(5), "scan still running 5 s after the unplug");
        std::thread::sleep(Duration::from_millis(5));
    };
    let took = unplugged.elapsed();
    eprintln!("scan noticed the unplug after {took:?}");
    assert!(took < Duration::from_secs(1), "scan took {took:?} to notice");
    assert_eq!(status.code(), Some(1));
    let (frames, st) = read_manifest(&emu.manifest_path());
    assert!(frames.len() >= 5 && !st.complete);
    assert_frames_true(&frames, &emu.truth());
}

#[test]
fn info_prints_the_controller_description() {
    let emu = Emulator::start(&["--camera-mode", "blank"]);
    let out = Command::new(BIN).args(["info", "--json", "--port", &emu.port]).output().unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["protocol"], 1);
    assert_eq!(v["counts_per_rev"], 36000);
    assert_eq!(v["facets"], 12);
    assert_eq!(v["lasers"], 2);
    assert_eq!(v["state"], "idle");
}

#[test]
fn bad_ports_and_arguments_fail_cleanly() {
    let out = Command::new(BIN).args(["info", "--port", "/dev/omni-no-such-port"]).output().unwrap();
    assert_eq!(out.status.code(), Some(1));
    let e = String::from_utf8_lossy(&out.stderr);
    assert!(e.contains("/dev/omni-no-such-port") && e.lines().count() == 1, "{e}");
    let dir = tempfile::tempdir().unwrap();
    let out = Command::new(BIN)
        .args(["scan", "--port", "/dev/null", "--angles", "0:30", "--frames"])
        .arg(dir.path())
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("start:stop:step"));
    // A port that is not there: no frames directory is made for a scan that never starts.
    let frames = dir.path().join("frames");
    let out = Command::new(BIN)
        .args(["scan", "--port", "/dev/omni-no-such-port", "--angles", "0:30:10", "--frames"])
        .arg(&frames)
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1), "{}", String::from_utf8_lossy(&out.stderr));
    assert!(!frames.exists(), "the frames directory was made");
    // An angle beyond the facet is refused after the handshake, with a status record.
    let emu = Emulator::start(&["--camera-mode", "blank"]);
    let out = emu.scan(&["--angles", "10,31"]);
    assert_eq!(out.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&out.stderr).contains("31° is outside the facet"));
    let (frames, status) = read_manifest(&emu.manifest_path());
    assert!(frames.is_empty() && !status.complete);
}

#[test]
fn a_timed_scan_stops_the_controller_and_accounts_for_every_trigger() {
    let emu = Emulator::start(&["--camera-mode", "blank", "--max-rate-hz", "40"]);
    let started = Instant::now();
    let out = emu.scan(&["--angles", "0,15", "--duration", "0.6", "--max-missing", "30"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert!(started.elapsed() < Duration::from_secs(5));
    let (frames, status) = read_manifest(&emu.manifest_path());
    assert_frames_true(&frames, &emu.truth());
    let fired = extra(&status, "controller_fired");
    // 0.6 s at 40 Hz, less the start-up: about 20 triggers.
    assert!((10..=30).contains(&fired), "{status:?}");
    assert_eq!(status.frames + status.frames_missing, fired, "{status:?}");
    assert!(status.complete);
}

/// A scan on the emulator with `stop` (e.g. `--revolutions 20`), sent SIGTERM after its third
/// frame: its output.
fn scan_terminated_after_three_frames(emu: &Emulator, stop: &[&str]) -> std::process::Output {
    let mut scan = Command::new(BIN)
        .args(["scan", "--port", &emu.port, "--angles", "0,15"])
        .args(stop)
        .arg("--frames")
        .arg(emu.frames())
        .arg("-o")
        .arg(emu.manifest_path())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let started = Instant::now();
    while std::fs::read_to_string(emu.manifest_path()).map(|t| t.matches("\"frame\"").count()).unwrap_or(0) < 3 {
        if scan.try_wait().unwrap().is_some() {
            let out = scan.wait_with_output().unwrap();
            panic!("the scan ended before its third frame: {}", String::from_utf8_lossy(&out.stderr));
        }
        assert!(started.elapsed() < Duration::from_secs(10), "scan produced no frames");
        std::thread::sleep(Duration::from_millis(10));
    }
    assert!(Command::new("kill").args(["-TERM", &scan.id().to_string()]).status().unwrap().success());
    scan.wait_with_output().unwrap()
}

#[test]
fn an_interrupted_scan_stops_the_controller_and_ends_its_manifest_with_a_status() {
    // Buffered, as in the tests below: a camera that misses a trigger on a loaded machine would
    // end the scan (--max-missing 0) before the signal under test.
    let emu = Emulator::start(&["--camera-mode", "blank", "--max-rate-hz", "40", "--buffered-camera"]);
    let out = scan_terminated_after_three_frames(&emu, &["--revolutions", "20"]);
    assert_eq!(out.status.code(), Some(1));
    let (frames, st) = read_manifest(&emu.manifest_path());
    assert!(!st.complete && st.errors.iter().any(|e| e.contains("interrupted")), "{st:?}");
    assert!(extra(&st, "controller_fired") < 480, "the controller was stopped: {st:?}");
    assert_eq!(st.frames + st.frames_missing, extra(&st, "controller_fired"), "{st:?}");
    assert_frames_true(&frames, &emu.truth());
}

#[test]
fn a_scan_until_stopped_ends_complete_on_sigterm() {
    let emu = Emulator::start(&["--camera-mode", "blank", "--max-rate-hz", "40", "--buffered-camera"]);
    let out = scan_terminated_after_three_frames(&emu, &["--until-stopped"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let (frames, st) = read_manifest(&emu.manifest_path());
    assert!(st.complete && st.errors.is_empty(), "{st:?}");
    assert_eq!(st.frames + st.frames_missing, extra(&st, "controller_fired"), "{st:?}");
    assert_frames_true(&frames, &emu.truth());
    let manifest = std::fs::read_to_string(emu.manifest_path()).unwrap();
    let header: serde_json::Value = serde_json::from_str(manifest.lines().next().unwrap()).unwrap();
    assert_eq!(header["live"], true, "a live capture's frames are marked transient: {header}");
    let both = Command::new(BIN)
        .args(["scan", "--port", "x", "--frames", "f", "--until-stopped", "--duration", "3"])
        .output()
        .unwrap();
    assert_eq!(both.status.code(), Some(2));
}

#[test]
fn a_persistent_emulator_serves_several_tool_runs() {
    // Buffered: the sessions are under test, not whether the camera keeps up on a loaded machine.
    let emu = Emulator::start(&["--camera-mode", "blank", "--max-rate-hz", "40", "--persist", "--buffered-camera"]);
    for _ in 0..2 {
        let out = Command::new(BIN).args(["info", "--port", &emu.port]).output().unwrap();
        assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
        assert!(String::from_utf8_lossy(&out.stdout).contains("36000 counts/rev"));
    }
    // Scan after scan: a controller that stays powered remembers the last session's command
    // ids and would answer them again without running them, so each session numbers anew.
    for run in 0..2 {
        let out = emu.scan(&["--angles", "0,15", "--facets", "0,6"]);
        assert!(out.status.success(), "scan {run}: {}", String::from_utf8_lossy(&out.stderr));
        let (frames, status) = read_manifest(&emu.manifest_path());
        assert_eq!((frames.len(), status.frames_missing), (4, 0), "scan {run}: {status:?}");
    }
}

#[test]
fn a_stalled_motor_ends_the_scan_with_an_error_and_a_status_record() {
    let emu = Emulator::start(&["--camera-mode", "blank", "--max-rate-hz", "40", "--stall-after", "5"]);
    let started = Instant::now();
    let out = emu.scan(&FAST);
    // The controller reports the stall 65.5 ms after the 5th trigger (its stall watch, as the
    // firmware's); the host stops at once instead of waiting for its own timeout (6.2 s).
    assert!(started.elapsed() < Duration::from_secs(4), "{:?}", started.elapsed());
    assert_eq!(out.status.code(), Some(1));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("fault=stall") && stderr.contains("lasers off"), "{stderr}");
    let (frames, status) = read_manifest(&emu.manifest_path());
    assert!(!status.complete && frames.len() <= 5, "{status:?}");
    assert!(status.errors.iter().any(|e| e.contains("fault=stall")), "{status:?}");
    assert_frames_true(&frames, &emu.truth());
}

#[test]
fn a_motor_stalled_before_the_index_times_the_scan_out() {
    // Nothing watches a run before its first index (the motor may still spin up): the host's own
    // timeout ends it, as with a controller that never reports a stall.
    let emu = Emulator::start(&["--camera-mode", "blank", "--max-rate-hz", "40", "--stall-after", "0"]);
    let started = Instant::now();
    let out = emu.scan(&FAST);
    // One revolution takes 0.6 s; the scan gives up at 2 x 0.6 + 5 s.
    assert!(started.elapsed() < Duration::from_secs(12), "{:?}", started.elapsed());
    assert_eq!(out.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&out.stderr).contains("still running"));
    let (frames, status) = read_manifest(&emu.manifest_path());
    assert!(!status.complete && frames.is_empty(), "{status:?}");
}

#[test]
fn emulate_renders_from_camera_scanner_and_scene_files_and_names_bad_ones() {
    use omni_formats::{CameraFile, CameraSpec, ScannerFile, write_doc};
    let files = tempfile::tempdir().unwrap();
    let (camera, scanner, scene) =
        (files.path().join("camera.json"), files.path().join("scanner.json"), files.path().join("scene.json"));
    write_doc(&camera, &CameraFile::new(CameraSpec::Hyperbolic(omni_simulator::paper_camera_scaled(48)))).unwrap();
    write_doc(&scanner, &ScannerFile::new(omni_model::TransmitterParams::paper())).unwrap();
    write_doc(&scene, &omni_simulator::paper_bench(omni_simulator::BenchObject::Sphere)).unwrap();
    let s = |p: &Path| p.to_str().unwrap().to_string();
    let emu = Emulator::start(&[
        "--camera",
        &s(&camera),
        "--scanner",
        &s(&scanner),
        "--scene",
        &s(&scene),
        "--max-rate-hz",
        "10",
        "--buffered-camera",
    ]);
    let out = emu.scan(&["--angles", "10,20", "--facets", "0"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let (frames, status) = read_manifest(&emu.manifest_path());
    assert_eq!((frames.len(), status.frames_missing), (2, 0), "{status:?}");
    assert_frames_true(&frames, &emu.truth());
    let png = std::fs::read(emu.frames().join(&frames[0].path)).unwrap();
    assert_eq!(u32::from_be_bytes(png[16..20].try_into().unwrap()), 48);

    std::fs::write(&camera, "{\"format\":\"omniscan.camera\",\"version\":1,\"model\":{\"kind\":\"spherical\"}}")
        .unwrap();
    let out = Command::new(BIN)
        .args(["emulate", "--camera", &s(&camera), "--scanner", &s(&scanner), "--frames"])
        .arg(files.path().join("frames"))
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1));
    let e = String::from_utf8_lossy(&out.stderr);
    assert!(e.contains("camera.json") && e.contains("spherical"), "{e}");
    assert!(out.stdout.is_empty(), "no device path for a failed start");
}

#[test]
fn missing_frames_beyond_max_missing_fail_the_scan() {
    // A wrong frames directory: every trigger goes without its frame.
    let emu = Emulator::start(&["--camera-mode", "blank", "--max-rate-hz", "40"]);
    let elsewhere = emu.dir.path().join("elsewhere");
    std::fs::create_dir(&elsewhere).unwrap();
    let out = Command::new(BIN)
        .args(["scan", "--port", &emu.port, "--angles", "0,15", "--facets", "0,6", "--frame-timeout-ms", "300"])
        .arg("--frames")
        .arg(&elsewhere)
        .arg("-o")
        .arg(emu.manifest_path())
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(err.contains("4 of 4 triggered frames missing") && err.contains("--max-missing 0"), "{err}");
    let (frames, status) = read_manifest(&emu.manifest_path());
    assert!(frames.is_empty() && !status.complete, "{status:?}");
    assert!(status.errors.iter().any(|e| e.contains("--max-missing")), "{status:?}");
}

/// A scan until stopped has no end to fail at: it stops at the first frame beyond the limit.
#[test]
fn a_scan_until_stopped_stops_at_once_when_frames_go_missing() {
    let emu = Emulator::start(&["--camera-mode", "blank", "--max-rate-hz", "40"]);
    let elsewhere = emu.dir.path().join("elsewhere");
    std::fs::create_dir(&elsewhere).unwrap();
    let t0 = std::time::Instant::now();
    let out =
        emu.scan_command(&elsewhere, &["--angles", "0,15", "--until-stopped", "--frame-timeout-ms", "300"]).output();
    let (out, took) = (out.unwrap(), t0.elapsed());
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(err.contains("1 triggered frame missing, more than --max-missing 0"), "{err}");
    assert!(took < std::time::Duration::from_secs(20), "stopped after {took:?}");
    let (_, status) = read_manifest(&emu.manifest_path());
    assert!(!status.complete, "{status:?}");
}

/// The virtual camera's size is bounded before the emulator opens its pseudo-terminal.
#[test]
fn an_emulated_camera_width_out_of_range_is_a_usage_error() {
    let dir = tempfile::tempdir().unwrap();
    for width in ["8", "8193", "2000000000"] {
        let out = Command::new(BIN).args(["emulate", "--width", width, "--frames"]).arg(dir.path()).output().unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "--width {width}: {err}");
        assert!(err.contains("--width must be in 16..=8192") && err.lines().count() == 1, "{err}");
    }
}
