//! Runs the real omni-calib-plane binary on a small synthetic rig (exact geometry, true camera,
//! pixel noise) and on broken inputs.

use omni_calib::plane::PlacedBoard;
use omni_calib::plane::synth::{corner_pixels, paper_camera, stripe_frame, two_board_rig};
use omni_formats::rig::{BoardCorners, BoardCornersFile, RigBoard, RigFile};
use omni_formats::stream::{Frame, Header, Record, StreamWriter, StripePoint};
use omni_formats::{CameraFile, CameraSpec, ScannerFile};
use omni_geom::rng::SplitMix64;
use omni_model::{HyperbolicParams, Transmitter, TransmitterParams};
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

const BIN: &str = env!("CARGO_BIN_EXE_omni-calib-plane");

fn run(args: &[&str]) -> Output {
    Command::new(BIN).args(args).output().unwrap()
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// Writes camera.json, rig.json, corners.json and stripes.jsonl (facet 0, α = 0…30° every 1°)
/// for the paper build into `dir`; `alpha_override` replaces the angle of frame 3.
fn dataset(dir: &Path, alpha_override: Option<f64>) -> [PathBuf; 4] {
    let camera = paper_camera();
    let truth = Transmitter::new(TransmitterParams::paper()).unwrap();
    let mut rng = SplitMix64::new(11);
    let rig = two_board_rig(550.0);
    let mut corners = vec![];
    for (board, pose) in &rig {
        let (pts, px) = corner_pixels(&camera, board, pose, 0.1, &mut rng);
        let c = pts
            .iter()
            .zip(&px)
            .map(|(b, p)| [(b[0] / board.square_mm).round(), (b[1] / board.square_mm).round(), p[0], p[1]])
            .collect();
        corners.push(BoardCorners { board: board.name.clone(), corners: c });
    }
    let placed: Vec<PlacedBoard> = rig.iter().map(|(b, p)| PlacedBoard::new(b, *p)).collect();
    let paths = ["camera.json", "rig.json", "corners.json", "stripes.jsonl"].map(|n| dir.join(n));
    let write = |p: &Path, v: serde_json::Value| std::fs::write(p, serde_json::to_vec_pretty(&v).unwrap()).unwrap();
    write(&paths[0], serde_json::to_value(CameraFile::new(CameraSpec::Hyperbolic(HyperbolicParams::paper()))).unwrap());
    write(&paths[1], serde_json::to_value(RigFile::new(rig.iter().map(|(b, _)| b.clone()).collect())).unwrap());
    write(&paths[2], serde_json::to_value(BoardCornersFile::new(corners)).unwrap());
    let mut w = StreamWriter::new(Vec::new(), "mem");
    w.write(&Record::Header(Header::new("test"))).unwrap();
    for i in 0..=30u64 {
        let s = stripe_frame(&camera, &truth, &placed, i, i as f64, 0, 0.15, 2.0, &mut rng);
        let alpha = if i == 3 { alpha_override.unwrap_or(i as f64) } else { i as f64 };
        w.write(&stripe_record(i, alpha, &s.pixels)).unwrap();
    }
    std::fs::write(&paths[3], w.into_inner()).unwrap();
    paths
}

fn fit_args<'a>(p: &'a [PathBuf; 4], out: &'a Path) -> Vec<&'a str> {
    vec![
        "fit",
        "--camera",
        p[0].to_str().unwrap(),
        "--rig",
        p[1].to_str().unwrap(),
        "--board-corners",
        p[2].to_str().unwrap(),
        "--stripes",
        p[3].to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
    ]
}

#[test]
fn fit_writes_a_scanner_whose_planes_match_the_truth_and_table_prints_them() {
    let dir = tempfile::tempdir().unwrap();
    let paths = dataset(dir.path(), None);
    let out = dir.path().join("scanner.json");
    let o = run(&fit_args(&paths, &out));
    assert!(o.status.success(), "{}", stderr(&o));
    let (file, fitted) = ScannerFile::load_polygon(&out).unwrap();
    if let Ok(dump) = std::env::var("PLANE_DUMP") {
        std::fs::copy(&out, dump).unwrap();
    }
    let report = file.report.unwrap();
    assert!(report["model"]["residual_rms_mm"].as_f64().unwrap() < 1.0, "{report}");
    assert_eq!(report["boards"].as_array().unwrap().len(), 2);
    assert!(report["model"]["parameters"].as_array().unwrap().iter().all(|p| p["std"].is_number()));
    // Frames at the ends of the sweep cross one board only: reported, not silently dropped.
    let refused = report["frames"].as_array().unwrap().iter().filter(|f| f["plane_refused"].is_string()).count();
    let with_plane = report["frames"].as_array().unwrap().iter().filter(|f| f["plane_rms_mm"].is_number()).count();
    assert!(with_plane >= 20, "{with_plane} frames with planes, {refused} refused");
    let truth = Transmitter::new(TransmitterParams::paper()).unwrap();
    for a in [5.0f64, 15.0, 25.0] {
        let t = truth.light_plane(a.to_radians(), 0, 0).unwrap().plane;
        let m = fitted.light_plane(a.to_radians(), 0, 0).unwrap().plane;
        // Board poses from 0.1 px corners limit the accuracy to a few hundredths of a degree.
        assert!(t.angle_to(&m).to_degrees() < 0.1, "α {a}: {}°", t.angle_to(&m).to_degrees());
    }
    let o = run(&["table", "--scanner", out.to_str().unwrap(), "--alpha", "0:30:15", "--laser", "0"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let text = String::from_utf8(o.stdout).unwrap();
    assert_eq!(text.lines().count(), 4, "{text}");
    assert!(text.lines().next().unwrap().contains("intercept_mm"));
    let o = run(&["table", "--scanner", out.to_str().unwrap(), "--alpha", "15", "--json"]);
    let rows: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(rows.as_array().unwrap().len(), 2);
    let slope = rows[0]["slope"].as_f64().unwrap();
    assert!(slope.abs() < 2e-3, "laser 0 plane at α = 15° is level: slope {slope}");
}

#[test]
fn bad_inputs_fail_cleanly_without_output() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("scanner.json");

    // A frame angle outside the facet's range.
    let paths = dataset(dir.path(), Some(42.0));
    let o = run(&fit_args(&paths, &out));
    assert_eq!(o.status.code(), Some(1));
    assert!(stderr(&o).contains("frame 3") && stderr(&o).contains("outside"), "{}", stderr(&o));
    assert!(!out.exists());

    // camera.json of an unknown version.
    let paths = dataset(dir.path(), None);
    let text = std::fs::read_to_string(&paths[0]).unwrap().replace("\"version\": 1", "\"version\": 7");
    std::fs::write(&paths[0], text).unwrap();
    let o = run(&fit_args(&paths, &out));
    assert_eq!(o.status.code(), Some(1));
    assert!(stderr(&o).contains("camera.json") && stderr(&o).contains("unsupported version 7"), "{}", stderr(&o));
    assert!(!out.exists());

    // A rig board the corners file does not mention: board not found.
    let paths = dataset(dir.path(), None);
    let text = std::fs::read_to_string(&paths[1]).unwrap().replace("\"right\"", "\"far\"");
    std::fs::write(&paths[1], text).unwrap();
    let o = run(&fit_args(&paths, &out));
    assert_eq!(o.status.code(), Some(1));
    assert!(stderr(&o).contains("corners.json") && stderr(&o).contains("right"), "{}", stderr(&o));
    assert!(!out.exists());

    // Stripes that miss the boards (all pixels in the blind centre): too few points everywhere.
    let paths = dataset(dir.path(), None);
    let mut w = StreamWriter::new(Vec::new(), "mem");
    w.write(&Record::Header(Header::new("test"))).unwrap();
    for i in 0..5u64 {
        let mut f = Frame::new(i, "f.png", 10.0, 0);
        f.stripe = Some(vec![StripePoint { u: 511.5, v: 511.5, intensity: 9.0, width: 2.0, quality: 0 }; 30]);
        w.write(&Record::Frame(Box::new(f))).unwrap();
    }
    std::fs::write(&paths[3], w.into_inner()).unwrap();
    let o = run(&fit_args(&paths, &out));
    assert_eq!(o.status.code(), Some(1));
    assert!(stderr(&o).contains("no usable frame"), "{}", stderr(&o));
    assert!(!out.exists());

    // A pose image without boards (uniform grey), and a truncated one.
    let paths = dataset(dir.path(), None);
    let mut grey = omni_vision::image_io::GrayImage::new(1024, 1024, 8);
    grey.data.iter_mut().for_each(|v| *v = 128);
    let pose = dir.path().join("pose.png");
    omni_vision::image_io::write_gray_png(&pose, &grey).unwrap();
    let mut args = fit_args(&paths, &out);
    args[5] = "--pose-image";
    args[6] = pose.to_str().unwrap();
    let o = run(&args);
    assert_eq!(o.status.code(), Some(1));
    assert!(stderr(&o).contains("pose.png") && stderr(&o).contains("not found"), "{}", stderr(&o));
    // Several pose images must show the same view: a second one of another size is refused.
    let small = dir.path().join("small.png");
    omni_vision::image_io::write_gray_png(&small, &omni_vision::image_io::GrayImage::new(512, 512, 8)).unwrap();
    let mut two = args.clone();
    two.insert(7, small.to_str().unwrap());
    let o = run(&two);
    assert_eq!(o.status.code(), Some(1));
    assert!(stderr(&o).contains("--pose-image") && stderr(&o).contains("512"), "{}", stderr(&o));
    let bytes = std::fs::read(&pose).unwrap();
    std::fs::write(&pose, &bytes[..bytes.len() / 2]).unwrap();
    let o = run(&args);
    assert_eq!(o.status.code(), Some(1));
    assert!(stderr(&o).contains("pose.png"), "{}", stderr(&o));
    assert!(!out.exists());

    // A usage error.
    let o = run(&["table", "--scanner", "x.json", "--alpha", "5:1:1"]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("--alpha"), "{}", stderr(&o));
}

#[test]
fn fit_finds_the_boards_in_a_rendered_pose_image() {
    use omni_simulator::{RenderOptions, Rig, Sensor, render_rig_pose_image};
    let dir = tempfile::tempdir().unwrap();
    let sensor = Sensor::paper();
    let board = omni_formats::BoardFile::new(6, 9, 40.0);
    let rig = Rig::standard(&board);
    // Two ambient images of the unmoved rig (independent noise), averaged by the tool.
    let poses = [1u64, 2].map(|seed| {
        let (image, _) = render_rig_pose_image(&sensor, &rig, &RenderOptions { seed, ..RenderOptions::calibration() });
        let path = dir.path().join(format!("pose{seed}.png"));
        image.to_png(&path).unwrap();
        path
    });
    let rig_boards: Vec<RigBoard> = ["left", "right"]
        .iter()
        .map(|n| RigBoard {
            name: n.to_string(),
            inner_cols: board.inner_cols,
            inner_rows: board.inner_rows,
            square_mm: board.square_mm,
            margin_mm: board.margin_mm,
            placement: 0,
        })
        .collect();
    let placed: Vec<PlacedBoard> = rig_boards.iter().zip(&rig.poses).map(|(b, p)| PlacedBoard::new(b, *p)).collect();
    // Stripes: exact geometry on the same boards, 0.1 px noise.
    let camera = paper_camera();
    let truth = Transmitter::new(TransmitterParams::paper()).unwrap();
    let mut rng = SplitMix64::new(3);
    let mut w = StreamWriter::new(Vec::new(), "mem");
    w.write(&Record::Header(Header::new("test"))).unwrap();
    for i in 0..=16u64 {
        let a = 8.0 + i as f64;
        let s = stripe_frame(&camera, &truth, &placed, i, a, 0, 0.1, 2.0, &mut rng);
        w.write(&stripe_record(i, a, &s.pixels)).unwrap();
    }
    let paths = ["camera.json", "rig.json", "stripes.jsonl"].map(|n| dir.path().join(n));
    let camera_file = CameraFile::new(CameraSpec::Hyperbolic(HyperbolicParams::paper()));
    std::fs::write(&paths[0], serde_json::to_vec_pretty(&camera_file).unwrap()).unwrap();
    std::fs::write(&paths[1], serde_json::to_vec_pretty(&RigFile::new(rig_boards)).unwrap()).unwrap();
    std::fs::write(&paths[2], w.into_inner()).unwrap();
    let out = dir.path().join("scanner.json");
    let p = |x: &PathBuf| x.to_str().unwrap().to_string();
    let args = [
        "fit".into(),
        "--camera".into(),
        p(&paths[0]),
        "--rig".into(),
        p(&paths[1]),
        "--pose-image".into(),
        p(&poses[0]),
        p(&poses[1]),
        "--stripes".into(),
        p(&paths[2]),
        "-o".into(),
        p(&out),
    ];
    let o = Command::new(BIN).args(&args).output().unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
    let (file, fitted) = ScannerFile::load_polygon(&out).unwrap();
    let report = file.report.unwrap();
    assert!(report["boards"].as_array().unwrap().iter().all(|b| b["source"] == "pose image"), "{}", report["boards"]);
    for a in [10.0f64, 16.0, 22.0] {
        let t = truth.light_plane(a.to_radians(), 0, 0).unwrap().plane;
        let m = fitted.light_plane(a.to_radians(), 0, 0).unwrap().plane;
        let err = t.angle_to(&m).to_degrees();
        // Corners found to ~0.03 px in the rendered image: boards within ~0.02°.
        assert!(err < 0.03, "α {a}: {err}°");
    }
}

/// The ridge stream's frame record of laser frame `seq` at mirror angle `alpha_deg` with the
/// given stripe pixels.
fn stripe_record(seq: u64, alpha_deg: f64, pixels: &[[f64; 2]]) -> Record {
    let mut f = Frame::new(seq, format!("{seq:06}.png"), alpha_deg, 0);
    f.stripe = Some(
        pixels.iter().map(|p| StripePoint { u: p[0], v: p[1], intensity: 200.0, width: 3.0, quality: 0 }).collect(),
    );
    Record::Frame(Box::new(f))
}

#[test]
fn the_summary_counts_frames_not_planes() {
    let dir = tempfile::tempdir().unwrap();
    let paths = dataset(dir.path(), None);
    let out = dir.path().join("scanner.json");
    let o = run(&fit_args(&paths, &out));
    let err = stderr(&o);
    assert!(o.status.success(), "{err}");
    let used: usize = err.split(" of 31 frames used").next().unwrap().rsplit(' ').next().unwrap().parse().unwrap();
    assert!((1..=31).contains(&used), "{err}");
    assert!(err.contains("light planes, one per frame and laser"), "{err}");
}

#[test]
fn a_pose_image_of_the_wrong_size_names_the_sizes() {
    let dir = tempfile::tempdir().unwrap();
    let paths = dataset(dir.path(), None);
    let out = dir.path().join("scanner.json");
    let small = dir.path().join("small.png");
    omni_vision::image_io::write_gray_png(&small, &omni_vision::image_io::GrayImage::new(512, 512, 8)).unwrap();
    let mut args = fit_args(&paths, &out);
    args[5] = "--pose-image";
    args[6] = small.to_str().unwrap();
    let o = run(&args);
    let err = stderr(&o);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(err.contains("small.png") && err.contains("512 × 512") && err.contains("1024 × 1024"), "{err}");
    assert!(!err.contains("not found"), "{err}");
}

#[test]
fn stripes_cut_short_are_warned_about_or_refused_with_strict() {
    let dir = tempfile::tempdir().unwrap();
    // The dataset's stripe stream has no status record.
    let paths = dataset(dir.path(), None);
    let out = dir.path().join("scanner.json");
    let mut args = fit_args(&paths, &out);
    args.push("--strict");
    let o = run(&args);
    let err = stderr(&o);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(
        err.contains("stripes.jsonl") && err.contains("without its status record") && err.contains("--strict"),
        "{err}"
    );
    assert!(!out.exists());
    let o = run(&fit_args(&paths, &out));
    let err = stderr(&o);
    assert!(o.status.success(), "{err}");
    assert!(err.contains("warning:") && err.contains("without its status record"), "{err}");
}

/// A fit whose model residual exceeds `--max-residual-mm` is refused and writes nothing: the
/// stripes do not belong to the boards (another scan's stream gave 14.7 mm, a sound rig 0.2).
#[test]
fn a_fit_too_far_from_its_stripes_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("scanner.json");
    let paths = dataset(dir.path(), None);
    let mut args = fit_args(&paths, &out);
    args.extend(["--max-residual-mm", "0.001"]);
    let o = run(&args);
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    let err = stderr(&o);
    assert!(
        err.contains("stripes.jsonl: the model's residual RMS is") && err.contains("above --max-residual-mm 0.001")
    );
    let errors: Vec<_> = err.lines().filter(|l| !l.contains("warning: ")).collect();
    assert_eq!(errors.len(), 1, "{err}");
    assert!(!out.exists());
    // The default limit passes a sound fit.
    let o = run(&fit_args(&paths, &out));
    assert!(o.status.success() && out.exists(), "{}", stderr(&o));
}
