//! End-to-end tests of the omni-calib-receiver binary.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_omni-calib-receiver"))
}

fn real_dir() -> PathBuf {
    PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../../../shared/data/real-omni-miniomni"))
}

fn write_board(dir: &Path, cols: u32, rows: u32) -> PathBuf {
    let path = dir.join(format!("board{cols}x{rows}.json"));
    let text = format!(
        "{{\"format\": \"omniscan.board\", \"version\": 1, \"inner_cols\": {cols}, \"inner_rows\": {rows}, \"square_mm\": 30.0}}"
    );
    std::fs::write(&path, text).unwrap();
    path
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

#[test]
fn calibrates_the_real_images_exports_and_reimports() {
    let dir = tempfile::tempdir().unwrap();
    let board = write_board(dir.path(), 7, 11);
    let camera = dir.path().join("camera.json");
    let corners = dir.path().join("corners.json");
    let overlay = dir.path().join("overlay");
    let out = bin()
        .arg("--board")
        .arg(&board)
        .arg("-o")
        .arg(&camera)
        .arg("--save-corners")
        .arg(&corners)
        .arg("--overlay")
        .arg(&overlay)
        .arg("--export-kalibr")
        .arg(dir.path().join("camchain.yaml"))
        .arg("--export-opencv")
        .arg(dir.path().join("omnidir.yaml"))
        .args(["--viewpoint-mm", "1,2,80"])
        .arg(real_dir())
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", stderr(&out));
    let cam: serde_json::Value = serde_json::from_slice(&std::fs::read(&camera).unwrap()).unwrap();
    assert_eq!(cam["model"]["kind"], "mei");
    // The exports written by the same run carry its viewpoint: imported, the same camera.
    for (import, file) in [("import-opencv", "omnidir.yaml"), ("import-kalibr", "camchain.yaml")] {
        let out = bin().arg(import).arg(dir.path().join(file)).args(["-o", "-"]).output().unwrap();
        assert!(out.status.success(), "{}", stderr(&out));
        let back: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
        assert_eq!(back["model"]["viewpoint_mm"], serde_json::json!([1.0, 2.0, 80.0]), "{file}");
    }
    let rms = cam["report"]["rms_px"].as_f64().unwrap();
    assert!(rms <= 0.4, "RMS {rms} px");
    assert!(cam["report"]["images_used"].as_u64().unwrap() >= 14);
    assert!(cam["report"]["parameters"]["xi"]["std"].as_f64().unwrap() > 0.0);
    // The lens's blur on the board edges: per image 0.56-0.64 px (MiniOmni1-15), median 0.60.
    let blur = &cam["report"]["lens_blur"];
    let sigma = blur["psf_sigma_px"].as_f64().unwrap();
    assert!((0.55..=0.65).contains(&sigma) && blur["images"] == 15, "{blur}");
    assert_eq!(cam["lens_blur_px"].as_f64(), Some(sigma));
    assert_eq!(std::fs::read_dir(&overlay).unwrap().count(), 15);
    let kalibr = std::fs::read_to_string(dir.path().join("camchain.yaml")).unwrap();
    assert!(kalibr.contains("camera_model: omni") && kalibr.contains("resolution: [752, 480]"), "{kalibr}");

    // Fitting from the saved corners with the polynomial model, then OCamCalib round trip.
    let txt = dir.path().join("calib_results.txt");
    let out = bin()
        .arg("--board")
        .arg(&board)
        .arg("--corners")
        .arg(&corners)
        .arg("--model")
        .arg("ocam")
        .arg("--export-ocam")
        .arg(&txt)
        .arg("--annulus")
        .arg("375.5,239.5,20,300")
        .args(["--viewpoint-mm", "0,0,80"])
        .arg("-o")
        .arg(dir.path().join("ocam.json"))
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", stderr(&out));
    let imported = dir.path().join("imported.json");
    let out = bin().arg("import-ocam").arg(&txt).arg("-o").arg(&imported).output().unwrap();
    assert!(out.status.success(), "{}", stderr(&out));
    let a: serde_json::Value = serde_json::from_slice(&std::fs::read(dir.path().join("ocam.json")).unwrap()).unwrap();
    let b: serde_json::Value = serde_json::from_slice(&std::fs::read(&imported).unwrap()).unwrap();
    assert_eq!(b["model"]["kind"], "ocam");
    assert_eq!(b["model"]["viewpoint_mm"], serde_json::json!([0.0, 0.0, 80.0]), "the run's viewpoint kept");
    // The fitted model is valid inside the given annulus.
    assert_eq!(a["model"]["outer_radius_px"], 300.0);
    assert_eq!(a["model"]["inner_radius_px"], 20.0);
    let (ca, cb) = (a["model"]["cx_px"].as_f64().unwrap(), b["model"]["cx_px"].as_f64().unwrap());
    assert!((ca - cb).abs() < 1e-5, "{ca} vs {cb}");
}

#[test]
fn wrong_board_size_and_unreadable_files_fail_without_output() {
    let dir = tempfile::tempdir().unwrap();
    let camera = dir.path().join("camera.json");
    // A 5 × 4 board: the real 7 × 11 grid is larger, so no image is usable.
    let small = write_board(dir.path(), 5, 4);
    let out = bin()
        .arg("--board")
        .arg(&small)
        .arg("-o")
        .arg(&camera)
        .arg(real_dir().join("MiniOmni1.jpg"))
        .arg(real_dir().join("MiniOmni2.jpg"))
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1), "{}", stderr(&out));
    assert!(stderr(&out).contains("calibration failed"), "{}", stderr(&out));
    assert!(stderr(&out).contains("does not fit the board"), "{}", stderr(&out));
    assert!(!camera.exists());

    // A truncated image names the file.
    let broken = dir.path().join("broken.jpg");
    let bytes = std::fs::read(real_dir().join("MiniOmni3.jpg")).unwrap();
    std::fs::write(&broken, &bytes[..bytes.len() / 3]).unwrap();
    let board = write_board(dir.path(), 7, 11);
    let out = bin().arg("--board").arg(&board).arg("-o").arg(&camera).arg(&broken).output().unwrap();
    assert_eq!(out.status.code(), Some(1));
    assert!(stderr(&out).contains("broken.jpg"), "{}", stderr(&out));
    assert!(!camera.exists());

    // Corners for another board size.
    let corners = dir.path().join("corners.json");
    std::fs::write(
        &corners,
        r#"{"format": "omniscan.corners", "version": 1, "width": 752, "height": 480, "inner_cols": 9, "inner_rows": 6, "images": []}"#,
    )
    .unwrap();
    let out = bin().arg("--board").arg(&board).arg("--corners").arg(&corners).arg("-o").arg(&camera).output().unwrap();
    assert_eq!(out.status.code(), Some(1));
    assert!(stderr(&out).contains("9 × 6 board"), "{}", stderr(&out));

    // An output in a missing directory is refused before any image is read, and the other
    // outputs are not written either (every output is put in place only once all succeed).
    let saved = dir.path().join("saved.json");
    let out = bin()
        .arg("--board")
        .arg(&board)
        .arg("-o")
        .arg(dir.path().join("nodir/camera.json"))
        .arg("--save-corners")
        .arg(&saved)
        .arg(&broken)
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1));
    assert!(stderr(&out).contains("nodir") && stderr(&out).lines().count() == 1, "{}", stderr(&out));
    assert!(!saved.exists());

    // Usage errors: exports that do not match the model; missing images.
    let out = bin().arg("--board").arg(&board).arg("--export-ocam").arg("x.txt").arg(&broken).output().unwrap();
    assert_eq!(out.status.code(), Some(2));
    let out = bin().arg("--board").arg(&board).output().unwrap();
    assert_eq!(out.status.code(), Some(2));
    // An annulus needs four numbers with 0 ≤ inner < outer radius.
    for bad in ["1,2,3", "1,2,300,20", "1,2,-1,20", "a,b,c,d"] {
        let out = bin().arg("--board").arg(&board).arg("--annulus").arg(bad).arg(&broken).output().unwrap();
        assert_eq!(out.status.code(), Some(2), "--annulus {bad}: {}", stderr(&out));
        assert!(stderr(&out).contains("--annulus"), "{}", stderr(&out));
    }
    assert!(!camera.exists());
}

/// `--annulus auto` finds the mirror rim in the real board images themselves (their per-pixel
/// range), calibrates with it (≥ 14 of 15 boards, RMS ≤ 0.4 px) and records it in the report;
/// its centre lies within 3 px of the fitted principal point (measured 1.3 px).
#[test]
fn annulus_auto_finds_the_rim_in_the_real_board_images() {
    let dir = tempfile::tempdir().unwrap();
    let board = write_board(dir.path(), 7, 11);
    let camera = dir.path().join("camera.json");
    let out =
        bin().arg("--board").arg(&board).arg("--annulus").arg("auto").arg("-o").arg(&camera).arg(real_dir()).output();
    let out = out.unwrap();
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(stderr(&out).contains("mirror annulus from --annulus auto"), "{}", stderr(&out));
    let cam: serde_json::Value = serde_json::from_slice(&std::fs::read(&camera).unwrap()).unwrap();
    let annulus: Vec<f64> =
        cam["report"]["annulus_px"].as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect();
    assert_eq!(annulus.len(), 4);
    assert_eq!(cam["model"]["outer_radius_px"].as_f64().unwrap(), annulus[3]);
    let (cx, cy) = (cam["model"]["cx_px"].as_f64().unwrap(), cam["model"]["cy_px"].as_f64().unwrap());
    let offset = (annulus[0] - cx).hypot(annulus[1] - cy);
    assert!(offset <= 3.0, "rim centre {annulus:?} is {offset} px from the principal point ({cx}, {cy})");
    assert!(cam["report"]["images_used"].as_u64().unwrap() >= 14);
    let rms = cam["report"]["rms_px"].as_f64().unwrap();
    assert!(rms <= 0.4, "RMS {rms} px");

    // find-annulus prints the same annulus for --annulus (3 decimals).
    let out = bin().arg("find-annulus").arg(real_dir()).output().unwrap();
    assert!(out.status.success(), "{}", stderr(&out));
    let printed: Vec<f64> =
        String::from_utf8_lossy(&out.stdout).trim().split(',').map(|v| v.parse().unwrap()).collect();
    assert_eq!(printed.len(), 4);
    for (p, a) in printed.iter().zip(&annulus) {
        assert!((p - a).abs() < 1e-3, "{printed:?} vs {annulus:?}");
    }
}

#[test]
fn rim_detection_failures_are_one_line_errors_without_output() {
    let dir = tempfile::tempdir().unwrap();
    let board = write_board(dir.path(), 7, 11);
    let camera = dir.path().join("camera.json");
    let one = real_dir().join("MiniOmni1.jpg");
    // One board image is no lit image: its rim is not a circle seen all round.
    let out = bin().arg("--board").arg(&board).arg("--rim-image").arg(&one).arg("-o").arg(&camera).arg(&one).output();
    let out = out.unwrap();
    assert_eq!(out.status.code(), Some(1), "{}", stderr(&out));
    let err = stderr(&out);
    assert!(err.contains("MiniOmni1.jpg") && err.contains("no mirror rim found"), "{err}");
    assert_eq!(err.trim().lines().count(), 1, "{err}");
    let out = bin().arg("find-annulus").arg(&one).output().unwrap();
    assert_eq!(out.status.code(), Some(1), "{}", stderr(&out));
    assert!(out.stdout.is_empty() && stderr(&out).contains("no mirror rim found"), "{}", stderr(&out));
    // An unreadable rim image names the file.
    let broken = dir.path().join("broken.png");
    std::fs::write(&broken, b"\x89PNG\r\n\x1a\n truncated").unwrap();
    let out =
        bin().arg("--board").arg(&board).arg("--rim-image").arg(&broken).arg("-o").arg(&camera).arg(&one).output();
    let out = out.unwrap();
    assert_eq!(out.status.code(), Some(1), "{}", stderr(&out));
    assert!(stderr(&out).contains("broken.png"), "{}", stderr(&out));
    // `auto` needs the board images; numbers and a rim image exclude each other.
    let corners = dir.path().join("corners.json");
    let out = bin().arg("--board").arg(&board).arg("--annulus").arg("auto").arg("--corners").arg(&corners).output();
    assert_eq!(out.unwrap().status.code(), Some(2));
    let mut both = bin();
    both.arg("--board").arg(&board).arg("--annulus").arg("1,2,3,4").arg("--rim-image").arg(&one).arg(&one);
    assert_eq!(both.output().unwrap().status.code(), Some(2));
    assert!(!camera.exists());
}

#[test]
fn a_huge_board_is_refused_before_anything_is_allocated() {
    let dir = tempfile::tempdir().unwrap();
    let board = write_board(dir.path(), 100_000, 6);
    let out = bin()
        .arg("--board")
        .arg(&board)
        .arg("-o")
        .arg(dir.path().join("camera.json"))
        .arg(real_dir())
        .output()
        .unwrap();
    let err = stderr(&out);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(err.contains("board100000x6.json") && err.contains("inner_cols") && err.contains("1000"), "{err}");
    assert_eq!(err.lines().count(), 1, "{err}");
}

#[test]
fn a_truncated_jpeg_is_refused_naming_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let board = write_board(dir.path(), 7, 11);
    let images = dir.path().join("boards");
    std::fs::create_dir(&images).unwrap();
    let grey: Vec<u8> = (0..96 * 64).map(|i| (i % 200) as u8).collect();
    let good = images.join("a.jpg");
    image::save_buffer(&good, &grey, 96, 64, image::ExtendedColorType::L8).unwrap();
    let bytes = std::fs::read(&good).unwrap();
    std::fs::write(images.join("b.jpg"), &bytes[..bytes.len() * 2 / 3]).unwrap();
    let out =
        bin().arg("--board").arg(&board).arg("-o").arg(dir.path().join("camera.json")).arg(&images).output().unwrap();
    let err = stderr(&out);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(err.contains("b.jpg") && err.contains("truncated JPEG"), "{err}");
    assert!(!dir.path().join("camera.json").exists());
}

#[test]
fn find_annulus_exits_cleanly_when_stdout_closes() {
    let (reader, writer) = std::io::pipe().unwrap();
    drop(reader);
    let out = bin().arg("find-annulus").arg(real_dir()).stdout(writer).output().unwrap();
    let err = stderr(&out);
    assert_eq!(out.status.code(), Some(0), "{err}");
    assert!(!err.contains("panicked"), "{err}");
}

fn write_mei_camera(dir: &Path) -> PathBuf {
    let path = dir.join("mei.json");
    let text = r#"{"format": "omniscan.camera", "version": 1, "model": {"kind": "mei", "xi": 0.93,
        "fx_px": 310.5, "fy_px": 311.25, "cx_px": 377.1, "cy_px": 239.7, "k1": -0.21, "k2": 0.034,
        "p1": 0.0012, "p2": -0.0007, "width": 752, "height": 480, "inner_radius_px": 40,
        "outer_radius_px": 235, "viewpoint_mm": [0, 0, 80]}}"#;
    std::fs::write(&path, text).unwrap();
    path
}

fn run_with_stdin(args: &[&std::ffi::OsStr], stdin: &str) -> Output {
    use std::io::Write as _;
    let mut child = bin()
        .args(args)
        .stdin(std::process::Stdio::piped())
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    // A query that fails on a bad line exits without reading the rest: the pipe may be closed.
    if let Err(e) = child.stdin.take().unwrap().write_all(stdin.as_bytes()) {
        assert_eq!(e.kind(), std::io::ErrorKind::BrokenPipe, "writing the tool's stdin: {e}");
    }
    child.wait_with_output().unwrap()
}

/// `query`: a pixel's ray, sent back as a point 1 m along it, comes back to the pixel (text and
/// JSON); unseen pixels say `none`; a bad line names its number and leaves no output file.
#[test]
fn query_answers_pixels_and_points_both_ways() {
    let dir = tempfile::tempdir().unwrap();
    let cam = write_mei_camera(dir.path());
    let q = |extra: &[&str], stdin: &str| {
        let mut args: Vec<&std::ffi::OsStr> = vec!["query".as_ref(), "--camera".as_ref(), cam.as_os_str()];
        args.extend(extra.iter().map(|a| std::ffi::OsStr::new(*a)));
        run_with_stdin(&args, stdin)
    };
    let out = q(&[], "# a comment\n577.1 239.7\n377.1 239.7\n");
    assert!(out.status.success(), "{}", stderr(&out));
    let text = String::from_utf8(out.stdout).unwrap();
    let lines: Vec<&str> = text.lines().collect();
    assert_eq!(lines.len(), 2, "{text}");
    assert_eq!(lines[1], "377.1 239.7 none", "the blind centre");
    let v: Vec<f64> = lines[0].split(' ').map(|t| t.parse().unwrap()).collect();
    assert_eq!(v[2..5], [0.0, 0.0, 80.0], "rays start at the viewpoint");
    let point: Vec<f64> = (0..3).map(|k| v[2 + k] + 1000.0 * v[5 + k]).collect();
    let out = q(&["--json"], &format!("{{\"point_mm\": [{}, {}, {}]}}\n", point[0], point[1], point[2]));
    assert!(out.status.success(), "{}", stderr(&out));
    let answer: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let (u, w) = (answer["px"][0].as_f64().unwrap(), answer["px"][1].as_f64().unwrap());
    assert!((u - 577.1).abs() < 1e-6 && (w - 239.7).abs() < 1e-6, "{answer}");

    let file = dir.path().join("answers.txt");
    let out = q(&["-o", file.to_str().unwrap()], "577.1 239.7\n1 2 3 4\n");
    assert_eq!(out.status.code(), Some(1));
    let err = stderr(&out);
    assert!(err.contains("stdin: line 2: expected 2 numbers (pixel u v) or 3"), "{err}");
    assert_eq!(err.lines().count(), 1, "{err}");
    assert!(!file.exists(), "no half-written answers");

    // Unreadable questions are the input's fault, named with their line.
    let bad = dir.path().join("bad.txt");
    std::fs::write(&bad, b"577.1 239.7\n\xff\xfe\n").unwrap();
    let out = q(&["-i", bad.to_str().unwrap()], "");
    let err = stderr(&out);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(err.contains("bad.txt: line 2: stream did not contain valid UTF-8"), "{err}");
    // A point far beyond where its coordinates' squares overflow: its direction's pixel.
    let along = |far: f64| format!("[{}, {}, {}]\n", far * v[5], far * v[6], far * v[7]);
    let out = q(&["--json"], &(along(1e90) + &along(1e300)));
    let text = String::from_utf8(out.stdout).unwrap();
    let pixels: Vec<serde_json::Value> =
        text.lines().map(|l| serde_json::from_str::<serde_json::Value>(l).unwrap()["px"].clone()).collect();
    assert!(pixels[0].is_array() && pixels[0] == pixels[1], "{text}");
}

/// `export` writes Kalibr (with `rostopic`, `cam_overlaps` and the frame), OpenCV and refuses a
/// model of the wrong kind; `import-kalibr`/`import-opencv` read them back to the same camera.
#[test]
fn export_and_import_kalibr_and_opencv_round_trip() {
    let dir = tempfile::tempdir().unwrap();
    let cam = write_mei_camera(dir.path());
    let original: serde_json::Value = serde_json::from_slice(&std::fs::read(&cam).unwrap()).unwrap();
    for (to, import) in [("kalibr", "import-kalibr"), ("opencv", "import-opencv")] {
        let file = dir.path().join(format!("{to}.yaml"));
        let out = bin().arg("export").arg(&cam).arg("--to").arg(to).arg("-o").arg(&file).output().unwrap();
        assert!(out.status.success(), "{}", stderr(&out));
        let text = std::fs::read_to_string(&file).unwrap();
        assert!(text.contains("(x, y, -z) of the omniscan world"), "{text}");
        if to == "kalibr" {
            assert!(text.contains("rostopic: /omni/image_raw") && text.contains("cam_overlaps: []"), "{text}");
        }
        let back = dir.path().join(format!("from_{to}.json"));
        let out = bin().arg(import).arg(&file).arg("-o").arg(&back).output().unwrap();
        assert!(out.status.success(), "{}", stderr(&out));
        let read: serde_json::Value = serde_json::from_slice(&std::fs::read(&back).unwrap()).unwrap();
        for key in ["xi", "fx_px", "fy_px", "cx_px", "cy_px", "k1", "k2", "p1", "p2", "width", "height"] {
            assert_eq!(read["model"][key], original["model"][key], "{to}: {key}");
        }
        let viewpoint = |v: &serde_json::Value| serde_json::from_value::<[f64; 3]>(v["model"]["viewpoint_mm"].clone());
        assert_eq!(viewpoint(&read).unwrap(), viewpoint(&original).unwrap(), "{to}: the viewpoint comes back");
        // --viewpoint-mm places the imported camera where the user says.
        let out = bin().arg(import).arg(&file).args(["--viewpoint-mm", "1,-2,3", "-o", "-"]).output().unwrap();
        let read: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
        assert_eq!(read["model"]["viewpoint_mm"], serde_json::json!([1.0, -2.0, 3.0]), "{to}");
    }
    let out = bin().arg("export").arg(&cam).arg("--to").arg("ocam").arg("-o").arg("-").output().unwrap();
    assert_eq!(out.status.code(), Some(1));
    assert!(stderr(&out).contains("--to ocam needs a camera of kind ocam, this one is mei"), "{}", stderr(&out));
    let bad = dir.path().join("bad.yaml");
    std::fs::write(&bad, "cam0:\n  camera_model: ds\n  distortion_model: radtan\n  resolution: [752, 480]\n").unwrap();
    let back = dir.path().join("x.json");
    let out = bin().arg("import-kalibr").arg(&bad).arg("-o").arg(&back).output().unwrap();
    assert_eq!(out.status.code(), Some(1));
    assert!(stderr(&out).contains("bad.yaml: cam0.camera_model: \"ds\" is not read"), "{}", stderr(&out));
    assert!(!back.exists());
}

/// The ordinary cameras go out to OpenCV's and Kalibr's files and come back the same; a pinhole
/// with k3 is not written as Kalibr's radtan (which has no k3), and K, D alone need --model.
#[test]
fn pinhole_and_fisheye_round_trip_through_opencv_and_kalibr() {
    let dir = tempfile::tempdir().unwrap();
    let pinhole = r#"{"kind": "pinhole", "fx_px": 740.3, "fy_px": 740.9, "cx_px": 668.2, "cy_px": 313.6,
        "k1": -0.3275, "k2": 0.1156, "p1": -5.6e-4, "p2": 5.4e-4, "k3": -0.0192, "width": 1280, "height": 720}"#;
    let fisheye = r#"{"kind": "fisheye", "fx_px": 725.95, "fy_px": 726.3, "cx_px": 673.5, "cy_px": 308.6,
        "k1": -0.0352, "k2": -0.0203, "k3": 0.0323, "k4": -0.0158, "width": 1280, "height": 720}"#;
    let radtan = pinhole.replace(r#""k3": -0.0192"#, r#""k3": 0.0"#);
    let cases = [
        ("pinhole", pinhole.to_string(), "opencv", vec![]),
        ("radtan", radtan, "kalibr", vec![]),
        ("fisheye", fisheye.to_string(), "opencv", vec!["--model", "fisheye"]),
        ("fisheye-k", fisheye.to_string(), "kalibr", vec![]),
    ];
    for (name, model, to, extra) in cases {
        let cam = dir.path().join(format!("{name}.json"));
        std::fs::write(&cam, format!(r#"{{"format": "omniscan.camera", "version": 1, "model": {model}}}"#)).unwrap();
        let file = dir.path().join(format!("{name}.yaml"));
        let out = bin().arg("export").arg(&cam).arg("--to").arg(to).arg("-o").arg(&file).output().unwrap();
        assert!(out.status.success(), "{}", stderr(&out));
        assert!(std::fs::read_to_string(&file).unwrap().contains("camera's frame (X, Y, Z), Z forward, is (x, y, -z)"));
        let back = dir.path().join(format!("{name}-back.json"));
        let out = bin().arg(format!("import-{to}")).args(&extra).arg(&file).arg("-o").arg(&back).output().unwrap();
        assert!(out.status.success(), "{name}: {}", stderr(&out));
        let a: serde_json::Value = serde_json::from_slice(&std::fs::read(&cam).unwrap()).unwrap();
        let b: serde_json::Value = serde_json::from_slice(&std::fs::read(&back).unwrap()).unwrap();
        for (key, value) in a["model"].as_object().unwrap() {
            assert_eq!(&b["model"][key], value, "{name}: {key}");
        }
    }
    let out = bin()
        .arg("export")
        .arg(dir.path().join("pinhole.json"))
        .arg("--to")
        .arg("kalibr")
        .arg("-o")
        .arg("-")
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1));
    assert!(stderr(&out).contains("--to kalibr needs k3 = 0 (Kalibr's radtan has no k3"), "{}", stderr(&out));
    let out = bin().arg("import-opencv").arg(dir.path().join("fisheye.yaml")).arg("-o").arg("-").output().unwrap();
    assert_eq!(out.status.code(), Some(1));
    assert!(stderr(&out).contains("--model pinhole or fisheye"), "{}", stderr(&out));
}

/// `convert` fits the target model to the source's rays and reports the difference; beyond the
/// tolerance it refuses and writes nothing.
#[test]
fn convert_reports_the_difference_and_refuses_beyond_the_tolerance() {
    let dir = tempfile::tempdir().unwrap();
    // The sensor's exact mirror camera (docs/FORMATS.md's example).
    let cam = dir.path().join("hyperbolic.json");
    let text = r#"{"format": "omniscan.camera", "version": 1, "model": {"kind": "hyperbolic", "a_mm": 35.33,
        "b_mm": 18.756, "fx_px": 1950.0, "fy_px": 1950.0, "cx_px": 511.5, "cy_px": 511.5, "width": 1024,
        "height": 1024, "rim_radius_mm": 25.0, "inner_radius_mm": 4.0, "camera_offset_mm": [0, 0, 0],
        "camera_tilt_deg": [0, 0]}, "lens_blur_px": 0.6}"#;
    std::fs::write(&cam, text).unwrap();
    let out_path = dir.path().join("ocam.json");
    let out = bin().arg("convert").arg(&cam).arg("--to").arg("ocam").arg("-o").arg(&out_path).output().unwrap();
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(stderr(&out).contains("converted to Ocam over"), "{}", stderr(&out));
    let c: serde_json::Value = serde_json::from_slice(&std::fs::read(&out_path).unwrap()).unwrap();
    assert_eq!(c["model"]["kind"], "ocam");
    assert_eq!(c["lens_blur_px"], 0.6, "the lens's blur stays with the camera");
    let viewpoint_z = c["model"]["viewpoint_mm"][2].as_f64().unwrap();
    assert!((viewpoint_z - 2.0 * 35.33f64.hypot(18.756)).abs() < 1e-9, "rays start at the focus 2c: {viewpoint_z}");
    let ray = c["report"]["max_ray_difference_deg"].as_f64().unwrap();
    let pixel = c["report"]["max_pixel_difference_px"].as_f64().unwrap();
    assert!(ray <= 0.01 && pixel <= 0.05, "{ray}° {pixel} px");
    // A tolerance below what the polynomial reaches: refused, no file.
    let strict = dir.path().join("strict.json");
    let out = bin()
        .arg("convert")
        .arg(&cam)
        .arg("--to")
        .arg("ocam")
        .arg("--max-ray-deg")
        .arg("1e-9")
        .arg("-o")
        .arg(&strict)
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1), "{}", stderr(&out));
    assert!(stderr(&out).contains("differs from the source by up to") && stderr(&out).contains("not written"));
    assert!(!strict.exists());
}

/// `--folds 3` on the real set prints and records the held-out RMS beside the training RMS, per
/// corner.
#[test]
fn held_out_rms_on_the_real_images() {
    let dir = tempfile::tempdir().unwrap();
    let board = write_board(dir.path(), 7, 11);
    let camera = dir.path().join("camera.json");
    let out = bin()
        .arg("--board")
        .arg(&board)
        .arg("--folds")
        .arg("3")
        .arg("--jackknife")
        .arg("-o")
        .arg(&camera)
        .arg(real_dir())
        .output()
        .unwrap();
    let err = stderr(&out);
    assert!(out.status.success(), "{err}");
    assert!(err.contains("px per corner (Euclidean, as OpenCV and Kalibr print;"), "{err}");
    assert!(err.contains("held-out RMS per corner (3-fold"), "{err}");
    assert!(err.contains("leave-one-image-out jackknife σ"), "{err}");
    let cam: serde_json::Value = serde_json::from_slice(&std::fs::read(&camera).unwrap()).unwrap();
    let r = &cam["report"];
    let (test, train) =
        (r["held_out"]["test_rms_per_corner_px"].as_f64().unwrap(), r["rms_per_corner_px"].as_f64().unwrap());
    assert!((r["rms_px"].as_f64().unwrap() * 2f64.sqrt() - train).abs() < 1e-12);
    assert!(test >= 0.9 * train && test < 1.0, "test {test} px, training {train} px");
    assert_eq!(r["warnings"], serde_json::json!([]));
    // The jackknife over these 15 images: 1.5-3.2 × the fit's own σ (cy 0.70 against 0.22 px,
    // fx 8.8 against 3.7 px): the corners' errors are not independent within an image.
    let p = r["parameters"].as_object().unwrap();
    for (name, v) in p {
        let (jk, own) = (v["jackknife_std"].as_f64().unwrap(), v["std"].as_f64().unwrap());
        assert!(jk > own && jk < 5.0 * own, "{name}: jackknife {jk}, fit {own}");
    }
}

/// A board file off by one row (7 × 10 for the real 7 × 11 board) calibrates (the corners are
/// labeled on a part of the board) but is warned about with the likely size, on stderr and in
/// the report; --non-central is for the hyperbolic model only.
#[test]
fn a_board_file_off_by_one_is_warned_about_with_the_likely_size() {
    let dir = tempfile::tempdir().unwrap();
    let camera = dir.path().join("camera.json");
    let images: Vec<PathBuf> = (1..=6).map(|k| real_dir().join(format!("MiniOmni{k}.jpg"))).collect();
    let out = bin().arg("--board").arg(write_board(dir.path(), 7, 10)).arg("-o").arg(&camera).args(&images).output();
    let out = out.unwrap();
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(stderr(&out).contains("the board is probably 7 × 11"), "{}", stderr(&out));
    let cam: serde_json::Value = serde_json::from_slice(&std::fs::read(&camera).unwrap()).unwrap();
    let warnings = cam["report"]["warnings"].as_array().unwrap();
    assert!(warnings.iter().any(|w| w.as_str().unwrap().contains("probably 7 × 11")), "{warnings:?}");
    let board = write_board(dir.path(), 7, 11);
    let out = bin().arg("--board").arg(&board).arg("--non-central").arg("-o").arg(&camera).args(&images).output();
    let out = out.unwrap();
    assert_eq!(out.status.code(), Some(1), "{}", stderr(&out));
    assert!(stderr(&out).contains("non-central fit is for the hyperbolic model"), "{}", stderr(&out));
}

/// A bad --viewpoint-mm or --annulus is refused (one line, exit 2) before the corners are
/// detected: no export, no corners file and no camera.json (the default output, in the working
/// directory) are written.
#[test]
fn a_bad_viewpoint_or_annulus_writes_no_file() {
    let dir = tempfile::tempdir().unwrap();
    let board = write_board(dir.path(), 7, 11);
    let work = dir.path().join("work");
    std::fs::create_dir(&work).unwrap();
    for (flag, bad) in [("--viewpoint-mm", "0,0"), ("--viewpoint-mm", "0,0,nan"), ("--annulus", "376,240,200,100")] {
        let out = bin()
            .current_dir(&work)
            .arg("--board")
            .arg(&board)
            .arg("--export-kalibr")
            .arg("camchain.yaml")
            .arg("--save-corners")
            .arg("corners.json")
            .arg(flag)
            .arg(bad)
            .arg(real_dir().join("MiniOmni1.jpg"))
            .arg(real_dir().join("MiniOmni2.jpg"))
            .output()
            .unwrap();
        let err = stderr(&out);
        assert_eq!(out.status.code(), Some(2), "{flag} {bad}: {err}");
        assert_eq!(err.trim().lines().count(), 1, "{err}");
        assert!(err.contains(flag) && err.contains(bad), "{err}");
        let written: Vec<_> = std::fs::read_dir(&work).unwrap().map(|e| e.unwrap().file_name()).collect();
        assert!(written.is_empty(), "{flag} {bad}: wrote {written:?}");
    }
}
