//! Tests of the tool sessions: option parsing and checks, the summary and report of a fit, a
//! calibration from a corners file, the conversions' errors and the query loop.

use super::*;
use crate::receiver::ImageReport;
use crate::receiver::query::{answer, parse_query};
use crate::receiver::tests::synthetic_boards;
use omni_formats::write_doc;
use omni_model::{HyperbolicCamera, HyperbolicParams};
use std::sync::Mutex;
use std::sync::atomic::{AtomicUsize, Ordering};

/// Collects what a session reports.
#[derive(Default)]
struct Lines {
    said: Mutex<Vec<String>>,
    warned: Mutex<Vec<String>>,
    detected: AtomicUsize,
}

impl Reporter for Lines {
    fn say(&self, line: &str) {
        self.said.lock().unwrap().push(line.to_string());
    }
    fn warn(&self, message: &str) {
        self.warned.lock().unwrap().push(message.to_string());
    }
    fn image_detected(&self) {
        self.detected.fetch_add(1, Ordering::Relaxed);
    }
}

fn usage(m: &str) -> Error {
    Error::Usage(m.to_string())
}

#[test]
fn annulus_numbers_parse_and_bad_ones_are_usage_errors() {
    assert_eq!(parse_annulus("511.5,511.5,102.5,493"), Ok([511.5, 511.5, 102.5, 493.0]));
    assert_eq!(parse_annulus(" 10, -2 ,0,3"), Ok([10.0, -2.0, 0.0, 3.0]));
    for bad in ["1,2,3", "1,2,3,4,5", "1,2,x,3,4", "1,2,5,3", "1,2,3,3", "1,2,-1,3", "nan,2,0,3", "1,inf,0,3", ""] {
        let want = format!("--annulus: expected CX,CY,R_IN,R_OUT in px with 0 ≤ R_IN < R_OUT, got {bad:?}");
        assert_eq!(parse_annulus(bad), Err(usage(&want)), "{bad}");
    }
}

#[test]
fn viewpoint_parses_three_finite_numbers() {
    assert_eq!(parse_viewpoint("0,0,80"), Ok([0.0, 0.0, 80.0]));
    assert_eq!(parse_viewpoint("-1.5, 2,3e1"), Ok([-1.5, 2.0, 30.0]));
    for bad in ["0,0", "0,0,0,0", "0,x,0", "0,nan,0"] {
        assert_eq!(parse_viewpoint(bad), Err(usage(&format!("--viewpoint-mm: expected X,Y,Z in mm, got {bad:?}"))));
    }
}

#[test]
fn annulus_auto_without_board_images_is_a_usage_error() {
    let out = Lines::default();
    let want = usage("--annulus auto needs board images (not --corners); give --rim-image or numbers");
    assert_eq!(annulus::given(Some("auto"), None, false), Err(want.clone()));
    assert_eq!(annulus::resolve(Some(&annulus::Given::Auto), &[], &out).err(), Some(want));
    let rim = Path::new("lit.png");
    assert_eq!(
        annulus::given(Some("1,2,0,3"), Some(rim), false),
        Ok(Some(annulus::Given::Numbers([1.0, 2.0, 0.0, 3.0])))
    );
    assert_eq!(annulus::given(None, Some(rim), true), Ok(Some(annulus::Given::RimImage(rim))));
    assert_eq!(annulus::given(Some("auto"), None, true), Ok(Some(annulus::Given::Auto)));
    assert_eq!(annulus::given(None, None, true), Ok(None));
    let given = annulus::resolve(Some(&annulus::Given::Numbers([1.0, 2.0, 0.0, 3.0])), &[], &out).unwrap().unwrap();
    assert_eq!((given.annulus, given.source), ([1.0, 2.0, 0.0, 3.0], None));
    assert!(annulus::resolve(None, &[], &out).unwrap().is_none());
    assert!(out.said.lock().unwrap().is_empty());
}

#[test]
fn find_annulus_names_the_file_or_directory_at_fault() {
    let dir = tempfile::tempdir().unwrap();
    let out = Lines::default();
    let err = find_annulus(&[dir.path().to_path_buf()], &out).unwrap_err();
    assert_eq!(err, Error::Failed(format!("{}: no images in directory", dir.path().display())));
    let missing = dir.path().join("missing.png");
    let err = find_annulus(std::slice::from_ref(&missing), &out).unwrap_err();
    assert!(matches!(&err, Error::Failed(m) if m.starts_with(&format!("{}: ", missing.display()))), "{err:?}");
}

#[test]
fn option_combinations_are_checked_first() {
    let dir = tempfile::tempdir().unwrap();
    let out = Lines::default();
    // The board file does not exist: the option checks come before it is read.
    let base = CalibrateOptions::new(dir.path().join("board.json"), vec![dir.path().to_path_buf()]);
    let cases = [
        (CalibrateOptions { export_ocam: Some("o.txt".into()), ..base.clone() }, "--export-ocam needs --model ocam"),
        (
            CalibrateOptions { export_kalibr: Some("k.yaml".into()), model: ModelKind::Ocam, ..base.clone() },
            "--export-kalibr needs --model mei, pinhole-radtan or fisheye (Kalibr's radtan has no k3)",
        ),
        (
            CalibrateOptions { export_kalibr: Some("k.yaml".into()), model: ModelKind::Pinhole, ..base.clone() },
            "--export-kalibr needs --model mei, pinhole-radtan or fisheye (Kalibr's radtan has no k3)",
        ),
        (
            CalibrateOptions { export_opencv: Some("o.yaml".into()), model: ModelKind::Hyperbolic, ..base.clone() },
            "--export-opencv needs --model mei, pinhole, pinhole-radtan or fisheye",
        ),
        (CalibrateOptions { huber_px: 0.0, ..base.clone() }, "--huber-px must be a positive number"),
        (CalibrateOptions { huber_px: f64::NAN, ..base.clone() }, "--huber-px must be a positive number"),
        (
            CalibrateOptions { overlay: Some("o".into()), corners: Some("c.json".into()), ..base.clone() },
            "--overlay needs images (it cannot be used with --corners)",
        ),
        (
            CalibrateOptions { viewpoint_mm: "0,0".into(), ..base.clone() },
            "--viewpoint-mm: expected X,Y,Z in mm, got \"0,0\"",
        ),
        (
            CalibrateOptions { annulus: Some("1,2,3".into()), ..base.clone() },
            "--annulus: expected CX,CY,R_IN,R_OUT in px with 0 ≤ R_IN < R_OUT, got \"1,2,3\"",
        ),
        (
            CalibrateOptions { annulus: Some("auto".into()), corners: Some("c.json".into()), ..base.clone() },
            "--annulus auto needs board images (not --corners); give --rim-image or numbers",
        ),
    ];
    for (opts, want) in cases {
        assert_eq!(calibrate(&opts, &out), Err(usage(want)));
    }
    let err = calibrate(&base, &out).unwrap_err();
    assert!(matches!(&err, Error::Failed(m) if m.contains("board.json")), "{err:?}");
}

/// A calibration of three images: one used, one without a board, one rejected as an outlier.
fn three_image_calibration() -> Calibration {
    let image = |name: &str, corners, rms_px, used, reason: Option<&str>| ImageReport {
        name: name.into(),
        corners,
        rms_px,
        used,
        reason: reason.map(str::to_string),
        pose: None,
    };
    Calibration {
        spec: CameraSpec::Hyperbolic(HyperbolicParams::paper()),
        rms_px: 0.25,
        images: vec![
            image("a.png", 54, Some(0.5), true, None),
            image("b.png", 0, None, false, Some("no board found")),
            image("c.png", 30, Some(4.0), false, None),
        ],
        param_names: vec!["fx".into(), "cx".into()],
        params: vec![312.25, -0.001],
        std_devs: vec![0.0123, 2.0],
        mirrored_labels: false,
        model_check: None,
    }
}

#[test]
fn summary_has_a_line_per_image_the_rms_and_a_line_per_parameter() {
    let lines = summary_lines(&three_image_calibration());
    let want = [
        "  a.png: 54 corners, RMS 0.707 px per corner",
        "  b.png: rejected: no board found",
        "  c.png: rejected",
        "RMS reprojection error 0.354 px per corner (Euclidean, as OpenCV and Kalibr print; 0.250 px per coordinate) over 1 of 3 images",
        "  fx = 3.122500e2 ± 1.23e-2",
        "  cx = -1.000000e-3 ± 2.00e0",
    ];
    assert_eq!(lines, want);
}

#[test]
fn report_adds_model_board_annulus_warnings_and_held_out() {
    let cal = three_image_calibration();
    let board = BoardFile::new(9, 6, 25.0);
    let held = HeldOut { folds: 3, test_rms_px: 0.5, train_rms_px: 0.25, test_corners: 108 };
    let warnings = vec!["only 1 usable board images".to_string()];
    let r = report(&cal, ModelKind::Hyperbolic, &board, Some([1.0, 2.0, 0.0, 3.0]), &warnings, Some(&held));
    assert_eq!(r["model"], "hyperbolic");
    assert_eq!(r["board"], serde_json::json!({"inner_cols": 9, "inner_rows": 6, "square_mm": 25.0}));
    assert_eq!(r["annulus_px"], serde_json::json!([1.0, 2.0, 0.0, 3.0]));
    assert_eq!(r["warnings"], serde_json::json!(["only 1 usable board images"]));
    assert_eq!(
        r["held_out"],
        serde_json::json!({"folds": 3, "test_rms_per_corner_px": 0.5, "train_rms_per_corner_px": 0.25, "test_corners": 108})
    );
    assert_eq!(
        (r["rms_px"].as_f64(), r["images_used"].as_u64(), r["images_rejected"].as_u64()),
        (Some(0.25), Some(1), Some(2))
    );
    let plain = report(&cal, ModelKind::Mei, &board, None, &[], None);
    assert_eq!(plain["model"], "mei");
    assert!(plain.get("annulus_px").is_none() && plain.get("held_out").is_none(), "{plain}");
    assert_eq!(plain["warnings"], serde_json::json!([]));
}

/// 12 synthetic boards (9 × 6 corners of 25 mm, 0.1 px noise) seen by the paper's camera, as a
/// corners file in `dir`; with the board file.
fn synthetic_corners(dir: &Path) -> (PathBuf, PathBuf) {
    let truth = HyperbolicCamera::new(HyperbolicParams::paper()).unwrap();
    let mut file = CornersFile::new(1024, 1024, 9, 6);
    for (obs, _) in synthetic_boards(&truth, 12, 0.1, 7) {
        let corners =
            obs.board_mm.iter().zip(&obs.pixels).map(|(b, p)| [b[0] / 25.0, b[1] / 25.0, p[0], p[1]]).collect();
        file.images.push(ImageCorners {
            name: format!("{}.png", obs.name),
            corners,
            reason: None,
            seen_board_size: None,
        });
    }
    file.images.push(ImageCorners {
        name: "empty.png".into(),
        corners: vec![],
        reason: Some("no board found".into()),
        seen_board_size: None,
    });
    let (corners, board) = (dir.join("corners.json"), dir.join("board.json"));
    write_doc(&corners, &file).unwrap();
    write_doc(&board, &BoardFile::new(9, 6, 25.0)).unwrap();
    (corners, board)
}

#[test]
fn calibrates_from_a_corners_file_and_writes_the_report() {
    let dir = tempfile::tempdir().unwrap();
    let (corners, board) = synthetic_corners(dir.path());
    let output = dir.path().join("camera.json");
    let kalibr = dir.path().join("camchain.yaml");
    let opts = CalibrateOptions {
        corners: Some(corners.clone()),
        output: output.clone(),
        export_kalibr: Some(kalibr.clone()),
        annulus: Some("512,512,0,500".into()),
        viewpoint_mm: "0,0,80".into(),
        ..CalibrateOptions::new(board.clone(), vec![])
    };
    let out = Lines::default();
    calibrate(&opts, &out).unwrap();
    let said = out.said.lock().unwrap().clone();
    // 13 image lines (the empty one last), then the RMS line.
    assert_eq!(said[12], "  empty.png: rejected: no board found", "{said:#?}");
    assert!(
        said[13].starts_with("RMS reprojection error ") && said[13].ends_with(" over 12 of 13 images"),
        "{said:#?}"
    );
    assert_eq!(out.detected.load(Ordering::Relaxed), 0, "corners were read, not detected");
    let file: CameraFile = read_doc(&output).unwrap();
    let CameraSpec::Mei(p) = &file.model else { panic!("{:?}", file.model) };
    assert_eq!(p.viewpoint_mm, [0.0, 0.0, 80.0]);
    let r = file.report.unwrap();
    assert_eq!((r["model"].as_str(), r["images_used"].as_u64()), (Some("mei"), Some(12)));
    assert_eq!(r["annulus_px"], serde_json::json!([512.0, 512.0, 0.0, 500.0]));
    // Noise of 0.1 px per coordinate: the fit leaves about that per coordinate.
    let rms = r["rms_px"].as_f64().unwrap();
    assert!(rms > 0.07 && rms < 0.12, "{rms}");
    assert!(std::fs::read_to_string(&kalibr).unwrap().contains("camera_model: omni"));

    // Bad options are refused before anything is read or written: no corners, overlay, export
    // or camera file, and nothing reported.
    let again = dir.path().join("again");
    std::fs::create_dir(&again).unwrap();
    let opts = CalibrateOptions {
        output: again.join("camera.json"),
        save_corners: Some(again.join("corners.json")),
        export_kalibr: Some(again.join("camchain.yaml")),
        export_opencv: Some(again.join("omnidir.yaml")),
        ..opts
    };
    let out = Lines::default();
    let cases = [
        (
            CalibrateOptions { viewpoint_mm: "0,0,x".into(), ..opts.clone() },
            "--viewpoint-mm: expected X,Y,Z in mm, got \"0,0,x\"",
        ),
        (
            CalibrateOptions { annulus: Some("512,512,500,0".into()), ..opts.clone() },
            "--annulus: expected CX,CY,R_IN,R_OUT in px with 0 ≤ R_IN < R_OUT, got \"512,512,500,0\"",
        ),
        (
            CalibrateOptions { overlay: Some(again.join("overlay")), ..opts.clone() },
            "--overlay needs images (it cannot be used with --corners)",
        ),
        (
            CalibrateOptions { annulus: Some("auto".into()), ..opts.clone() },
            "--annulus auto needs board images (not --corners); give --rim-image or numbers",
        ),
    ];
    for (opts, want) in cases {
        assert_eq!(calibrate(&opts, &out), Err(usage(want)));
    }
    assert_eq!(std::fs::read_dir(&again).unwrap().count(), 0, "files written for bad options");
    assert!(out.said.lock().unwrap().is_empty() && out.warned.lock().unwrap().is_empty());
    // The same options with good numbers write all four files.
    calibrate(&opts, &out).unwrap();
    assert_eq!(std::fs::read_dir(&again).unwrap().count(), 4);
}

#[test]
fn corners_for_another_board_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let (corners, _) = synthetic_corners(dir.path());
    let board = dir.path().join("board7x5.json");
    write_doc(&board, &BoardFile::new(7, 5, 25.0)).unwrap();
    let opts = CalibrateOptions { corners: Some(corners.clone()), ..CalibrateOptions::new(board, vec![]) };
    let want = format!("{}: corners are for a 9 × 6 board but the board file says 7 × 5", corners.display());
    assert_eq!(calibrate(&opts, &Lines::default()), Err(Error::Failed(want)));
}

#[test]
fn export_of_the_wrong_kind_names_the_camera() {
    let dir = tempfile::tempdir().unwrap();
    let camera = dir.path().join("camera.json");
    write_doc(&camera, &CameraFile::new(CameraSpec::Hyperbolic(HyperbolicParams::paper()))).unwrap();
    let out = Lines::default();
    for (to, needs) in [("ocam", "ocam"), ("kalibr", "mei, pinhole or fisheye"), ("opencv", "mei, pinhole or fisheye")]
    {
        let opts = ExportOptions {
            camera: camera.clone(),
            to: to.into(),
            rostopic: "/t".into(),
            output: dir.path().join("x"),
        };
        let want = format!("{}: --to {to} needs a camera of kind {needs}, this one is hyperbolic", camera.display());
        assert_eq!(export_camera(&opts, &out), Err(Error::Failed(want)));
    }
    assert!(!dir.path().join("x").exists());
}

#[test]
fn query_answers_each_question_in_order_and_stops_at_a_bad_line() {
    let dir = tempfile::tempdir().unwrap();
    let camera = dir.path().join("camera.json");
    write_doc(&camera, &CameraFile::new(CameraSpec::Hyperbolic(HyperbolicParams::paper()))).unwrap();
    let cam = HyperbolicCamera::new(HyperbolicParams::paper()).unwrap();
    let input = dir.path().join("questions.txt");
    std::fs::write(&input, "600 240\n\n100 200 -50\n").unwrap();
    let output = dir.path().join("answers.txt");
    let opts = QueryOptions { camera: camera.clone(), input: input.clone(), output: output.clone(), json: false };
    query(&opts).unwrap();
    let want: String = ["600 240", "100 200 -50"]
        .iter()
        .map(|q| answer(&cam, parse_query(q).unwrap().unwrap(), false) + "\n")
        .collect();
    assert_eq!(std::fs::read_to_string(&output).unwrap(), want);
    assert_eq!(want.lines().count(), 2);

    std::fs::write(&input, "600 240\n1 2 3 4\n").unwrap();
    let bad_out = dir.path().join("bad.txt");
    let err = query(&QueryOptions { output: bad_out.clone(), ..opts }).unwrap_err();
    let Error::Failed(m) = &err else { panic!("{err:?}") };
    assert!(m.starts_with(&format!("{}: line 2: ", input.display())), "{m}");
    assert!(!bad_out.exists(), "a failed query writes no file");
}
