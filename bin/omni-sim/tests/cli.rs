//! The omni-sim binary end to end: files written, streams readable, errors clear.

use omni_formats::stream::{Record, StreamReader};
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

#[path = "../../../tests/support/devices.rs"]
mod devices;
use devices::writes_into_devices;

fn sim(args: &[&str], dir: &Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_omni-sim")).args(args).current_dir(dir).output().unwrap()
}

fn ok(out: &Output) {
    assert!(out.status.success(), "exit {:?}: {}", out.status.code(), String::from_utf8_lossy(&out.stderr));
}

fn testdata(rel: &str) -> String {
    PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../../testdata")).join(rel).display().to_string()
}

/// A 256 × 256 paper sensor in `dir/sensor` (small images keep the tests fast).
fn small_sensor(dir: &Path) {
    ok(&sim(&["sensor", "--preset", "paper", "--width", "256", "-o", "sensor"], dir));
}

#[test]
fn sensor_files_carry_the_imperfections() {
    let dir = tempfile::tempdir().unwrap();
    let args = [
        "sensor",
        "--preset",
        "paper",
        "-o",
        "s",
        "--camera-offset",
        "0.3,-0.1,0.5",
        "--camera-tilt",
        "0.1,-0.2",
        "--principal-point-offset",
        "1.5,-2",
        "--facet-errors",
        "0.02",
        "--encoder-offset",
        "-0.05",
        "--seed",
        "4",
    ];
    ok(&sim(&args, dir.path()));
    let (cam, _) = omni_formats::CameraFile::load(&dir.path().join("s/camera.json")).unwrap();
    let omni_formats::CameraSpec::Hyperbolic(p) = cam.model else { panic!("not hyperbolic") };
    assert_eq!(p.camera_offset_mm, [0.3, -0.1, 0.5]);
    assert_eq!(p.camera_tilt_deg, [0.1, -0.2]);
    assert_eq!((p.cx_px, p.cy_px), (513.0, 509.5));
    assert_eq!((p.fx_px, p.width), (1950.0, 1024));
    let (scanner, _) = omni_formats::ScannerFile::load(&dir.path().join("s/scanner.json")).unwrap();
    let tx = scanner.transmitter.polygon().unwrap();
    assert_eq!(tx.polygon.facet_errors.len(), 12);
    assert_eq!(tx.polygon.encoder_zero_deg, -0.05);
}

#[test]
fn scan_writes_frames_manifest_and_truth_deterministically() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    small_sensor(d);
    let scene = testdata("scenes/plane.json");
    let scan = |frames: &str, out: &str| {
        let args = [
            "scan",
            "--camera",
            "sensor/camera.json",
            "--scanner",
            "sensor/scanner.json",
            "--scene",
            &scene,
            "--angles",
            "16:22:2",
            "--frames",
            frames,
            "--laser-off",
            "--seed",
            "9",
            "-o",
            out,
            "--truth",
            "truth.jsonl",
        ];
        ok(&sim(&args, d));
    };
    scan("f1", "scan.jsonl");
    scan("f2", "-");
    let text = std::fs::read_to_string(d.join("scan.jsonl")).unwrap();
    let records: Vec<Record> = StreamReader::new(text.as_bytes(), "scan.jsonl").map(|r| r.unwrap()).collect();
    assert_eq!(records.len(), 5);
    let Record::Header(h) = &records[0] else { panic!("no header") };
    assert_eq!(h.frames_dir.as_deref(), Some("f1"));
    for (i, r) in records[1..4].iter().enumerate() {
        let Record::Frame(f) = r else { panic!("record {i} is not a frame") };
        assert_eq!((f.seq, f.alpha_deg, f.facet, f.lasers.clone()), (i as u64, 16.0 + 2.0 * i as f64, 0, vec![0, 1]));
        let png = std::fs::read(d.join("f1").join(&f.path)).unwrap();
        assert_eq!(png, std::fs::read(d.join("f2").join(&f.path)).unwrap(), "same seed, same PNG");
        assert!(d.join("f1").join(f.ambient_path.as_ref().unwrap()).exists());
    }
    let Record::Status(s) = &records[4] else { panic!("no status") };
    assert!(s.complete && s.frames == 3);
    let truth = std::fs::read_to_string(d.join("truth.jsonl")).unwrap();
    assert_eq!(truth.lines().count(), 4);
    let rec: omni_simulator::TruthRecord = serde_json::from_str(truth.lines().nth(2).unwrap()).unwrap();
    assert_eq!(rec.alpha_deg, 18.0);
    assert!(rec.points.len() > 100 && rec.points.iter().all(|p| (p[0] - 500.0).abs() < 1e-6));
}

#[test]
fn sixteen_bit_frames() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    small_sensor(d);
    let args = [
        "scan",
        "--camera",
        "sensor/camera.json",
        "--scanner",
        "sensor/scanner.json",
        "--scene",
        &testdata("scenes/sphere.json"),
        "--angles",
        "20",
        "--frames",
        "f",
        "--bit-depth",
        "16",
        "-o",
        "m.jsonl",
    ];
    ok(&sim(&args, d));
    let f = omni_simulator::Frame16::from_png(&d.join("f/frame_000000.png")).unwrap();
    assert_eq!((f.bit_depth, f.width), (16, 256));
    assert!(f.data.iter().any(|v| *v > 255));
}

#[test]
fn bad_input_is_refused_with_a_clear_message_and_no_output() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    small_sensor(d);
    let text = std::fs::read_to_string(testdata("scenes/sphere.json")).unwrap();
    std::fs::write(d.join("torus.json"), text.replace("\"sphere\"", "\"torus\"")).unwrap();
    std::fs::write(d.join("negative.json"), text.replace("50.0", "-50.0")).unwrap();
    let board_above = r#"{"format":"omniscan.scene","version":1,"objects":[{"type":"checkerboard",
        "centre_mm":[0,0,3000],"normal":[0,0,-1],"up":[1,0,0],"square_mm":30,"inner_cols":9,"inner_rows":6}]}"#;
    std::fs::write(d.join("above.json"), board_above).unwrap();
    for (scene, expect) in [
        ("torus.json", "unknown variant `torus`"),
        ("negative.json", "radius_mm must be a positive"),
        ("above.json", "never enters the camera's field of view"),
        ("missing.json", "missing.json"),
    ] {
        let args = [
            "scan",
            "--camera",
            "sensor/camera.json",
            "--scanner",
            "sensor/scanner.json",
            "--scene",
            scene,
            "--angles",
            "20",
            "--frames",
            "f",
            "-o",
            "m.jsonl",
        ];
        let out = sim(&args, d);
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{scene}: {err}");
        assert!(err.starts_with("omni-sim: error: ") && err.contains(scene) && err.contains(expect), "{err}");
        assert_eq!(err.lines().count(), 1, "{err}");
        assert!(!d.join("m.jsonl").exists(), "no manifest after an error");
    }
    let out = sim(
        &[
            "scan",
            "--camera",
            "sensor/camera.json",
            "--scanner",
            "sensor/scanner.json",
            "--scene",
            "x.json",
            "--angles",
            "0:30:-1",
            "--frames",
            "f",
        ],
        d,
    );
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("--angles"));
}

#[test]
fn optics_out_of_range_name_the_field() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    small_sensor(d);
    let scene = testdata("scenes/plane.json");
    // A scan of the small sensor with the given extra options.
    let scan = |extra: &[&str]| {
        let mut args = vec!["scan", "--camera", "sensor/camera.json", "--scanner", "sensor/scanner.json"];
        args.extend(["--scene", &scene, "--angles", "20", "--frames", "f", "-o", "m.jsonl"]);
        args.extend(extra);
        sim(&args, d)
    };
    for (flag, value, expect) in [
        ("--f-number", "0", "f_number"),
        ("--f-number", "-4", "f_number"),
        ("--wavelength-nm", "100", "wavelength_nm"),
        ("--wavelength-nm", "2500", "wavelength_nm"),
        ("--pixel-pitch-um", "0", "pixel_pitch_um"),
        ("--blur-px", "0.05", "diffraction limit"),
        ("--laser-gain", "-1", "--laser-gain must be a non-negative number, got -1"),
        ("--ambient-gain", "inf", "--ambient-gain must be a non-negative number, got inf"),
        ("--focus-mm", "-5", "focus_mm"),
        ("--focus-mm", "5", "beyond the 24 px"),
    ] {
        let out = scan(&[&format!("{flag}={value}")]);
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{flag} {value}: {err}");
        assert!(err.contains(expect) && err.lines().count() == 1, "{flag} {value}: {err}");
        assert!(!d.join("m.jsonl").exists());
    }
    // The idealised sensor has no lens to set; a focus distance and one blur exclude each other.
    assert_eq!(scan(&["--ideal", "--f-number", "8"]).status.code(), Some(2));
    for extra in [&["--focus-mm", "90", "--blur-px", "1"], &["--focus-mm", "90", "--defocus-px", "1"]] {
        let out = scan(extra);
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{extra:?}: {err}");
        assert!(err.contains("focus") && err.lines().count() == 1, "{extra:?}: {err}");
    }
    assert!(!d.join("m.jsonl").exists());
    // Focused, the frame renders, blurred differently from the default's one defocus; a camera
    // file focused at a distance renders the same, and one blur given on the command line
    // replaces its focus.
    let frame = |extra: &[&str]| {
        let _ = std::fs::remove_dir_all(d.join("f"));
        ok(&scan(extra));
        std::fs::read(d.join("f/frame_000000.png")).unwrap()
    };
    let (focused, plain) = (frame(&["--focus-mm", "85"]), frame(&[]));
    assert_ne!(focused, plain);
    let mut camera: serde_json::Value =
        serde_json::from_slice(&std::fs::read(d.join("sensor/camera.json")).unwrap()).unwrap();
    camera["optics"]["defocus_px"] = 0.0.into();
    camera["optics"]["focus_mm"] = 85.0.into();
    std::fs::write(d.join("sensor/camera.json"), serde_json::to_vec(&camera).unwrap()).unwrap();
    assert_eq!(frame(&[]), focused);
    assert_eq!(frame(&["--defocus-px", "1.5"]), plain);
    // `sensor --focus-mm` writes that camera file; an impossible focus writes nothing.
    ok(&sim(&["sensor", "--width", "256", "--focus-mm", "85", "-o", "focused"], d));
    let written: serde_json::Value =
        serde_json::from_slice(&std::fs::read(d.join("focused/camera.json")).unwrap()).unwrap();
    assert_eq!(written["optics"], camera["optics"]);
    let out = sim(&["sensor", "--width", "256", "--focus-mm", "5", "-o", "blurred"], d);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(err.contains("--focus-mm") && err.contains("focus farther") && !d.join("blurred").exists(), "{err}");
}

#[test]
fn boards_and_rig() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    small_sensor(d);
    let board = testdata("boards/board_9x6.json");
    ok(&sim(
        &["boards", "--camera", "sensor/camera.json", "--board", &board, "--count", "3", "--seed", "2", "--out", "b"],
        d,
    ));
    let truth: serde_json::Value =
        serde_json::from_slice(&std::fs::read(d.join("b/boards_truth.json")).unwrap()).unwrap();
    let images = truth["images"].as_array().unwrap();
    assert_eq!(images.len(), 3);
    for img in images {
        assert!(d.join("b").join(img["path"].as_str().unwrap()).exists());
        assert_eq!(img["corners"].as_array().unwrap().len(), 54);
        assert!(img["corners"].as_array().unwrap().iter().any(|c| !c.is_null()));
    }
    let args = [
        "rig",
        "--camera",
        "sensor/camera.json",
        "--scanner",
        "sensor/scanner.json",
        "--board",
        &board,
        "--angles",
        "18,22",
        "--laser-off",
        // At 256 px each pixel sees 16 times the area: the realistic stripe needs more power.
        "--laser-gain",
        "4",
        "--out",
        "r",
    ];
    ok(&sim(&args, d));
    let files = [
        "pose.png",
        "frame_000000.png",
        "frame_000001.png",
        "scan.jsonl",
        "rig.json",
        "board_poses.json",
        "board_corners.json",
        "scene.json",
        "rig_truth.json",
        "truth.jsonl",
    ];
    for f in files {
        assert!(d.join("r").join(f).exists(), "{f}");
    }
    let text = std::fs::read_to_string(d.join("r/scan.jsonl")).unwrap();
    let frames: Vec<_> = StreamReader::new(text.as_bytes(), "scan.jsonl")
        .filter_map(|r| match r.unwrap() {
            Record::Frame(f) => Some(f),
            _ => None,
        })
        .collect();
    assert_eq!(frames.len(), 2);
    for f in &frames {
        // The ambient frame shows the lit-by-room checkerboard the stripe detector must subtract.
        let ambient = omni_simulator::Frame16::from_png(&d.join("r").join(f.ambient_path.as_ref().unwrap())).unwrap();
        let laser = omni_simulator::Frame16::from_png(&d.join("r").join(&f.path)).unwrap();
        assert!(ambient.data.iter().any(|v| *v > 30), "ambient frame shows the boards");
        let gain = |t: u16| laser.data.iter().zip(&ambient.data).filter(|(l, a)| **l > **a + t).count();
        let max_gain = laser.data.iter().zip(&ambient.data).map(|(l, a)| l.saturating_sub(*a)).max().unwrap();
        eprintln!("{}: {} px > ambient + 20, {} px > ambient + 40, max gain {max_gain}", f.path, gain(20), gain(40));
        assert!(gain(20) > 20, "the laser frame adds a stripe over the ambient one");
    }
    check_rig_files(&d.join("r"), &board);
}

/// The rig files parse with the omni-formats readers and agree with the simulator's own record.
fn check_rig_files(dir: &Path, board_path: &str) {
    use omni_formats::read_doc;
    use omni_formats::rig::{BoardCornersFile, BoardPosesFile, RigFile};
    let board: omni_formats::BoardFile = read_doc(Path::new(board_path)).unwrap();
    let rig: RigFile = read_doc(&dir.join("rig.json")).unwrap();
    rig.validate().unwrap();
    let names: Vec<&str> = rig.boards.iter().map(|b| b.name.as_str()).collect();
    assert_eq!(names, ["left", "right"]);
    for b in &rig.boards {
        assert_eq!((b.inner_cols, b.inner_rows, b.square_mm), (board.inner_cols, board.inner_rows, board.square_mm));
        assert_eq!((b.margin_mm, b.placement), (board.margin_mm, 0));
    }
    let truth: serde_json::Value = serde_json::from_slice(&std::fs::read(dir.join("rig_truth.json")).unwrap()).unwrap();
    assert_eq!(truth["format"], "omniscan.sim-rig");
    let poses: BoardPosesFile = read_doc(&dir.join("board_poses.json")).unwrap();
    poses.validate().unwrap();
    assert_eq!(poses.poses.len(), 2);
    for (k, p) in poses.poses.iter().enumerate() {
        assert_eq!(p.board, names[k]);
        let t: [f64; 3] = serde_json::from_value(truth["poses"][k]["translation_mm"].clone()).unwrap();
        assert_eq!(p.translation_mm, t);
        // The standard rig stands vertically on the +x side, about 370–620 mm out.
        assert!(p.translation_mm[0] > 300.0 && p.translation_mm[0] < 650.0, "{:?}", p.translation_mm);
    }
    let corners: BoardCornersFile = read_doc(&dir.join("board_corners.json")).unwrap();
    let cols = board.inner_cols as usize;
    for (k, c) in corners.boards.iter().enumerate() {
        assert_eq!(c.board, names[k]);
        let visible: Vec<(usize, [f64; 2])> = truth["corners"][k]
            .as_array()
            .unwrap()
            .iter()
            .enumerate()
            .filter_map(|(i, v)| serde_json::from_value::<Option<[f64; 2]>>(v.clone()).unwrap().map(|px| (i, px)))
            .collect();
        assert!(visible.len() >= 6, "board {k}: only {} corners visible", visible.len());
        assert_eq!(c.corners.len(), visible.len());
        for (&[i, j, u, v], &(idx, px)) in c.corners.iter().zip(&visible) {
            assert_eq!([i, j, u, v], [(idx % cols) as f64, (idx / cols) as f64, px[0], px[1]]);
        }
    }
    let scene: omni_formats::scene::SceneFile = read_doc(&dir.join("scene.json")).unwrap();
    assert_eq!(scene.objects.len(), 2);
}

#[test]
fn help_teaches() {
    let out = sim(&["--help"], Path::new("."));
    ok(&out);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.contains("Examples:") && text.contains("omni-sim scan") && text.contains("f = 1950 px"));
    assert_eq!(sim(&["scan"], Path::new(".")).status.code(), Some(2));
    let rig = sim(&["rig", "--help"], Path::new("."));
    let text = String::from_utf8_lossy(&rig.stdout);
    for f in ["rig.json", "board_poses.json", "board_corners.json", "scene.json", "rig_truth.json", "--laser-off"] {
        assert!(text.contains(f), "omni-sim rig --help names {f}");
    }
}

#[test]
fn manifest_into_dev_null_and_a_fifo() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    small_sensor(d);
    let scene = testdata("scenes/plane.json");
    let text = writes_into_devices(d, |o| {
        let args = ["scan", "--camera", "sensor/camera.json", "--scanner", "sensor/scanner.json", "--scene", &scene];
        let mut args = args.to_vec();
        args.extend(["--angles", "20", "--frames", "f", "--ideal", "-o", o]);
        sim(&args, d)
    });
    assert!(String::from_utf8_lossy(&text).contains("\"type\":\"status\""));
}

#[test]
fn an_interrupted_scan_leaves_no_temporary_frame() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    small_sensor(d);
    let scene = testdata("scenes/plane.json");
    let frames = d.join("f");
    let count = |dir: &Path, temp: bool| {
        std::fs::read_dir(dir).map_or(0, |r| {
            r.filter_map(|e| e.ok())
                .filter(|e| e.file_name().to_string_lossy().contains("omniscan-tmp") == temp)
                .count()
        })
    };
    let mut child = Command::new(env!("CARGO_BIN_EXE_omni-sim"))
        .current_dir(d)
        .args(["scan", "--camera", "sensor/camera.json", "--scanner", "sensor/scanner.json", "--scene", &scene])
        .args(["--angles", "0:30:0.05", "--frames", "f", "--ideal", "-o", "m.jsonl"])
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let t0 = std::time::Instant::now();
    while count(&frames, false) < 4 {
        assert!(t0.elapsed().as_secs() < 60, "no frames written");
        std::thread::sleep(std::time::Duration::from_millis(10));
    }
    assert!(Command::new("kill").arg("-INT").arg(child.id().to_string()).status().unwrap().success());
    let status = child.wait().unwrap();
    assert!(!status.success(), "{status:?}");
    assert_eq!(count(&frames, true), 0, "temporary frames left");
    assert_eq!(count(d, true), 0);
    assert!(!d.join("m.jsonl").exists());
}

#[test]
fn a_facet_off_the_polygon_and_angles_far_outside_it_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    small_sensor(d);
    let scene = testdata("scenes/plane.json");
    for (extra, expect) in
        [(["--facet", "12", "--angles", "20"], "--facet"), (["--facet", "0", "--angles", "95"], "--angles")]
    {
        let mut args =
            vec!["scan", "--camera", "sensor/camera.json", "--scanner", "sensor/scanner.json", "--scene", &scene];
        args.extend(["--frames", "f", "-o", "m.jsonl"]);
        args.extend(extra);
        let out = sim(&args, d);
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{extra:?}: {err}");
        assert!(err.contains(expect) && (err.contains("12 facets") || err.contains("95")), "{err}");
        assert!(!d.join("m.jsonl").exists() && !d.join("f").exists());
    }
}

/// Sizes given on the command line are bounded before anything is allocated or written.
#[test]
fn board_counts_and_sensor_widths_out_of_range_are_usage_errors() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    small_sensor(d);
    let board = testdata("boards/board_9x6.json");
    for count in ["0", "10001", "4000000000"] {
        let out =
            sim(&["boards", "--camera", "sensor/camera.json", "--board", &board, "--count", count, "--out", "b"], d);
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "--count {count}: {err}");
        assert!(err.contains("--count") && err.lines().count() == 1, "{err}");
        assert!(!d.join("b").exists(), "no output directory after a usage error");
    }
    for width in ["8", "8193"] {
        let out = sim(&["sensor", "--preset", "paper", "--width", width, "-o", "w"], d);
        assert_eq!(out.status.code(), Some(2), "--width {width}");
        assert!(String::from_utf8_lossy(&out.stderr).contains("--width"));
        assert!(!d.join("w").exists());
    }
}

#[test]
fn real_stripes_colour_bayer_and_jpeg_frames() {
    let dir = tempfile::tempdir().unwrap();
    small_sensor(dir.path());
    let plane = testdata("scenes/plane.json");
    let base = ["scan", "--camera", "sensor/camera.json", "--scanner", "sensor/scanner.json", "--scene", &plane];
    let run = |extra: &[&str]| sim(&[&base[..], extra].concat(), dir.path());
    // A real-shaped saturated stripe through an RGGB mosaic, saved as JPEG, with laser-off frames.
    let jpeg = [
        "--angles",
        "20",
        "--lasers",
        "0",
        "--ideal",
        "--profile",
        "real",
        "--stripe-fwhm-px",
        "8",
        "--laser-gain",
        "30",
        "--bloom",
        "columns",
        "--halo",
        "0.02,8",
        "--colour",
        "rgb",
        "--bayer",
        "rggb",
        "--gamma",
        "2.2",
        "--format",
        "jpeg",
        "--laser-off",
        "--frames",
        "j",
        "-o",
        "j.jsonl",
        "--truth",
        "j_truth.jsonl",
    ];
    ok(&run(&jpeg));
    for name in ["j/frame_000000.jpg", "j/ambient_000000.jpg"] {
        let img = image::open(dir.path().join(name)).unwrap();
        assert!(matches!(img, image::DynamicImage::ImageRgb8(_)), "{name}: a colour JPEG");
    }
    let records: Vec<Record> =
        StreamReader::open(&dir.path().join("j.jsonl")).unwrap().collect::<Result<_, _>>().unwrap();
    let Record::Frame(f) = &records[1] else { panic!("{:?}", records[1]) };
    assert_eq!((f.path.as_str(), f.ambient_path.as_deref()), ("frame_000000.jpg", Some("ambient_000000.jpg")));
    let truth = std::fs::read_to_string(dir.path().join("j_truth.jsonl")).unwrap();
    let frame: serde_json::Value = serde_json::from_str(truth.lines().nth(1).unwrap()).unwrap();
    assert_eq!(frame["profile"]["shape"], "tailed");
    assert!(frame["sheet_fwhm_mm"][0].as_f64().unwrap() > 1.0, "{}", frame["sheet_fwhm_mm"]);
    // The raw mosaic of a BGGR sensor, 16-bit PGM.
    ok(&run(&[
        "--angles",
        "20",
        "--colour",
        "raw",
        "--bayer",
        "bggr",
        "--bit-depth",
        "16",
        "--format",
        "pgm",
        "--frames",
        "r",
    ]));
    let pgm = std::fs::read(dir.path().join("r/frame_000000.pgm")).unwrap();
    assert!(pgm.starts_with(b"P5\n256 256\n65535\n"), "{:?}", &pgm[..20]);
    // The default Gaussian run keeps its truth records as they were.
    ok(&run(&["--angles", "20", "--frames", "g", "-o", "g.jsonl", "--truth", "g_truth.jsonl"]));
    let truth = std::fs::read_to_string(dir.path().join("g_truth.jsonl")).unwrap();
    assert!(!truth.contains("profile") && !truth.contains("sheet_fwhm_mm"));
    // Options that do not fit together are usage errors naming the option.
    for (args, says) in [
        (&["--colour", "raw", "--frames", "x"][..], "--bayer"),
        (&["--colour", "rgb", "--format", "pgm", "--frames", "x"][..], "--format pgm"),
        (&["--bayer", "rggb", "--frames", "x"][..], "--colour"),
        (&["--format", "jpeg", "--jpeg-quality", "0", "--frames", "x"][..], "--jpeg-quality"),
        (&["--tail", "0.2,4,2", "--frames", "x"][..], "--tail"),
        (&["--ideal", "--stripe-fwhm-px", "1", "--frames", "x"][..], "narrower than the optics"),
        (&["--bloom", "columns", "--bloom-spill", "2", "--frames", "x"][..], "spill"),
    ] {
        let out = run(args);
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{args:?}: {err}");
        assert!(err.contains(says) && err.lines().count() == 1, "{args:?}: {err}");
    }
    let out = sim(
        &["boards", "--camera", "sensor/camera.json", "--board", "b.json", "--out", "b", "--colour", "rgb"],
        dir.path(),
    );
    assert_eq!(out.status.code(), Some(2));
}

/// The simulator renders through the polygon: a scanner file of fixed light planes is refused in
/// one line naming its kind, before anything is written.
#[test]
fn a_fixed_plane_scanner_is_refused_naming_its_kind() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    small_sensor(d);
    let fixed = r#"{"format": "omniscan.scanner", "version": 2, "transmitter": {"kind": "fixed_planes",
        "planes": [{"laser": 0, "normal": [0.05, 0.91, -0.41], "distance_mm": 6.6}]}}"#;
    std::fs::write(d.join("fixed.json"), fixed).unwrap();
    let scene = testdata("scenes/sphere.json");
    let args = [
        "scan",
        "--camera",
        "sensor/camera.json",
        "--scanner",
        "fixed.json",
        "--scene",
        &scene,
        "--angles",
        "20",
        "--frames",
        "f",
        "-o",
        "m.jsonl",
    ];
    let out = sim(&args, d);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert_eq!(
        err,
        "omni-sim: error: fixed.json: field transmitter.kind: transmitter kind \"fixed_planes\" cannot be used here: this needs kind \"polygon\" (the rotating polygon mirror)\n"
    );
    assert!(!d.join("m.jsonl").exists() && !d.join("f").exists());
}

/// Output places that cannot work are refused before anything is rendered: `-` or a file where
/// a directory goes, a manifest or truth file in a directory that does not exist; and options
/// that act on laser light are refused for board images, which have none.
#[test]
fn impossible_outputs_and_options_without_effect_are_refused_before_rendering() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    small_sensor(d);
    std::fs::write(d.join("a_file"), "x").unwrap();
    let scene = testdata("scenes/plane.json");
    let scan = |frames: &str, out: &str, truth: &str| {
        let mut args = vec!["scan", "--camera", "sensor/camera.json", "--scanner", "sensor/scanner.json"];
        args.extend(["--scene", &scene, "--angles", "16:22:2", "--frames", frames, "-o", out]);
        if !truth.is_empty() {
            args.extend(["--truth", truth]);
        }
        sim(&args, d)
    };
    let board = testdata("boards/board_9x6.json");
    let boards = |extra: &[&str]| {
        let mut args = vec!["boards", "--camera", "sensor/camera.json", "--board", &board, "--count", "1"];
        args.extend(["--out", "b"]);
        args.extend(extra);
        sim(&args, d)
    };
    let cases: Vec<(Output, i32, &str)> = vec![
        (sim(&["sensor", "--preset", "paper", "-o", "-"], d), 2, "--output: names a directory, and `-`"),
        (sim(&["sensor", "--preset", "paper", "-o", "a_file"], d), 1, "a_file: is a file, not a directory"),
        (scan("f1", "nodir/s.jsonl", ""), 1, "nodir/s.jsonl: directory nodir"),
        (scan("f2", "s.jsonl", "nodir/t.jsonl"), 1, "nodir/t.jsonl: directory nodir"),
        (scan("a_file", "s.jsonl", ""), 1, "a_file: is a file, not a directory (--frames)"),
        (scan("f3", "-", "-"), 2, "--truth and -o both name -"),
        (scan("f4", "s.jsonl", "./s.jsonl"), 2, "need a file each"),
        (boards(&["--laser-gain", "60"]), 2, "act on the laser's light"),
        (boards(&["--no-speckle"]), 2, "act on the laser's light"),
    ];
    for (out, code, says) in cases {
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(code), "{err}");
        assert!(err.contains(says) && err.lines().count() == 1, "{says}: {err}");
    }
    for never in ["-", "f1", "f2", "f3", "f4", "s.jsonl", "b"] {
        assert!(!d.join(never).exists(), "{never} was made");
    }
}
