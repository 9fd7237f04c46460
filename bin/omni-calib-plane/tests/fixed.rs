//! `omni-calib-plane fixed` on the real hand-held laser frames (../shared/data/real-laser-handheld,
//! README there) and on bad input: a board file that does not match, frames without a board,
//! too few usable frames, a scanner file of a kind a tool cannot use.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

const BIN: &str = env!("CARGO_BIN_EXE_omni-calib-plane");

/// The receiver calibration of the hand-held camera (omni-calib-receiver --model mei on
/// im18-im36, 0.304 px RMS), as numbers so that these tests need no receiver fit.
const CAMERA: &str = r#"{"format": "omniscan.camera", "version": 1, "model": {"kind": "mei",
  "xi": 1.9124743513073124, "fx_px": 2117.3173110827324, "fy_px": 2118.3693609729116,
  "cx_px": 673.046087049862, "cy_px": 313.01701346572486, "k1": -0.3827004133878569,
  "k2": 0.479775246825181, "p1": -0.002875096947052103, "p2": 0.00020702947400256963,
  "width": 1280, "height": 720}}"#;

fn board(cols: u32, rows: u32) -> String {
    format!(
        r#"{{"format": "omniscan.board", "version": 1, "inner_cols": {cols}, "inner_rows": {rows}, "square_mm": 5, "margin_mm": 0}}"#
    )
}

fn frame(k: u32) -> String {
    let dir = PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../../../shared/data/real-laser-handheld"));
    dir.join(format!("im{k}.png")).display().to_string()
}

/// The frame number [`run`] gives as a frame with no board in it: an evenly lit, empty colour
/// frame of the camera's size, written beside the other files as `blank.png`. (Every real
/// stripe frame shows a board the detector accepts.)
const NO_BOARD: u32 = 0;

fn no_board_frame(dir: &Path) -> String {
    let (width, height) = (1280, 720);
    let blank = omni_simulator::RgbFrame { width, height, data: vec![90; 3 * (width * height) as usize], bit_depth: 8 };
    let path = dir.join("blank.png");
    std::fs::write(&path, blank.encode(omni_simulator::FrameFormat::Png).unwrap()).unwrap();
    path.display().to_string()
}

fn run(dir: &Path, board_text: &str, frames: &[u32]) -> Output {
    run_with(dir, board_text, frames, &[])
}

fn run_with(dir: &Path, board_text: &str, frames: &[u32], extra: &[&str]) -> Output {
    std::fs::write(dir.join("camera.json"), CAMERA).unwrap();
    std::fs::write(dir.join("board.json"), board_text).unwrap();
    let mut args: Vec<String> =
        ["fixed", "--camera", "camera.json", "--board", "board.json", "--report", "report.json"]
            .iter()
            .map(|s| s.to_string())
            .collect();
    args.extend(["-o".into(), "scanner.json".into()]);
    args.extend(extra.iter().map(|s| s.to_string()));
    args.extend(frames.iter().map(|&k| if k == NO_BOARD { no_board_frame(dir) } else { frame(k) }));
    Command::new(BIN).current_dir(dir).args(&args).output().unwrap()
}

fn text(b: &[u8]) -> String {
    String::from_utf8_lossy(b).into_owned()
}

#[test]
fn frames_without_a_board_are_named_and_skipped_and_scanner_json_is_fixed_planes() {
    let dir = tempfile::tempdir().unwrap();
    let out = run(dir.path(), &board(9, 6), &[3, 4, NO_BOARD, 12]);
    let (so, se) = (text(&out.stdout), text(&out.stderr));
    assert!(out.status.success(), "{se}");
    assert!(so.contains("skipped") && so.contains("blank.png: board not found"), "{so}");
    assert!(so.contains("leave-one-frame-out RMS"), "{so}");
    let (file, model) = omni_formats::ScannerFile::load(&dir.path().join("scanner.json")).unwrap();
    assert_eq!((file.version, model.kind()), (2, "fixed_planes"));
    let report: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.path().join("report.json")).unwrap()).unwrap();
    assert_eq!(report["format"], "omniscan.fixed_plane_report");
    assert_eq!(report["report"]["frames"].as_array().unwrap().len(), 3);
    // Each frame's saturated stripe points on the board are counted, and the frames where they
    // are more than a quarter are named in one warning (im3 and im12 here: 27 and 39 %).
    let mut saturated = Vec::new();
    for f in report["report"]["frames"].as_array().unwrap() {
        let (n, on_board) = (f["saturated_points"].as_u64().unwrap(), f["board_points"].as_u64().unwrap());
        assert!(n <= on_board, "{f}");
        if 4 * n > on_board {
            saturated.push(f["name"].as_str().unwrap().rsplit('/').next().unwrap().to_string());
        }
    }
    let warnings: Vec<&str> = se.lines().filter(|l| l.contains("saturated")).collect();
    assert_eq!(warnings.len(), usize::from(!saturated.is_empty()), "{se}");
    for name in &saturated {
        assert!(warnings[0].contains(&format!("{name} ")), "{name} not in {se}");
    }
    assert!(!saturated.is_empty(), "no frame with its stripe largely saturated: {report}");
    // The table of a polygon tool refuses the fixed plane in one line naming the kind.
    let t = Command::new(BIN).current_dir(dir.path()).args(["table", "--scanner", "scanner.json"]).output().unwrap();
    assert_eq!(t.status.code(), Some(1));
    assert_eq!(
        text(&t.stderr),
        "omni-calib-plane: error: scanner.json: field transmitter.kind: transmitter kind \"fixed_planes\" cannot be used here: this needs kind \"polygon\" (the rotating polygon mirror)\n"
    );
}

#[test]
fn fewer_than_two_usable_frames_is_one_line_and_no_output() {
    let dir = tempfile::tempdir().unwrap();
    let out = run(dir.path(), &board(9, 6), &[3, NO_BOARD]);
    let se = text(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{se}");
    assert_eq!(se.lines().count(), 1, "{se}");
    assert!(se.starts_with("omni-calib-plane: error: 1 usable frame of 2, at least 2 needed; skipped: "), "{se}");
    assert!(se.contains("blank.png: board not found"), "{se}");
    assert!(!dir.path().join("scanner.json").exists());
}

#[test]
fn a_board_file_that_does_not_match_is_named() {
    let dir = tempfile::tempdir().unwrap();
    let out = run(dir.path(), &board(7, 5), &[3, 4, 12]);
    let se = text(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{se}");
    assert_eq!(se.lines().count(), 1, "{se}");
    assert!(se.contains("9 × 6"), "{se}");
    assert!(!dir.path().join("scanner.json").exists());
}

/// im1's stripe runs on the paper's white border, 6 mm above the printed pattern: with a board
/// file that gives no border its board is found but does not carry the stripe, so the frame is
/// named with the reason, and with how many stripe points lie how far beyond the pattern, and
/// skipped. The two frames left give the plane (each frame's stripe lies in its board's plane,
/// and im4 holds most points: the robust fit scores planes frame by frame, or it took im4's board
/// plane for the light's). A board file that gives the border (margin_mm 7.5) uses im1 too, and
/// `--margin-mm` overrides the file.
#[test]
fn a_board_that_does_not_carry_the_stripe_is_named_and_skipped() {
    let dir = tempfile::tempdir().unwrap();
    let frames_used = |dir: &Path| {
        let report: serde_json::Value =
            serde_json::from_slice(&std::fs::read(dir.join("report.json")).unwrap()).unwrap();
        report["report"]["frames"].as_array().unwrap().len()
    };
    let out = run(dir.path(), &board(9, 6), &[3, 4, 1]);
    let (so, se) = (text(&out.stdout), text(&out.stderr));
    assert!(out.status.success(), "{se}");
    assert!(so.starts_with("board: 9 × 6 inner corners, 5 mm squares; stripe points kept up to 0 mm beyond the printed pattern (margin_mm of the board file)\n"), "{so}");
    let skipped = so
        .lines()
        .find(|l| l.contains("im1.png: the board does not carry the stripe: "))
        .unwrap_or_else(|| panic!("{so}"));
    // "…; 579 more lie on the board's plane beyond the border kept (0 mm past the printed pattern), the middle half 6.1 mm past it: …"
    let more: usize =
        skipped.split("; ").nth(1).and_then(|t| t.split(' ').next()).and_then(|n| n.parse().ok()).unwrap();
    assert!(more >= 400 && skipped.contains("give its white border as margin_mm"), "{skipped}");
    let out_mm: f64 = skipped
        .split("the middle half ")
        .nth(1)
        .and_then(|t| t.split(['-', ' ']).next())
        .and_then(|v| v.parse().ok())
        .unwrap();
    assert!((4.0..=8.0).contains(&out_mm), "{skipped}");
    assert_eq!(frames_used(dir.path()), 2);
    let bordered = board(9, 6).replace(r#""margin_mm": 0"#, r#""margin_mm": 7.5"#);
    let out = run(dir.path(), &bordered, &[3, 4, 1]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    assert!(!text(&out.stdout).contains("skipped"), "{}", text(&out.stdout));
    assert_eq!(frames_used(dir.path()), 3);
    let out = run_with(dir.path(), &bordered, &[3, 4, 1], &["--margin-mm", "0"]);
    assert!(out.status.success() && text(&out.stdout).contains("im1.png: the board does not carry"));
    assert!(text(&out.stdout).contains("kept up to 0 mm beyond the printed pattern (--margin-mm)"));
    assert_eq!(frames_used(dir.path()), 2);
}

/// A board file naming more corners than the board has: the frames that show the board whole
/// (im1, im2, im5: the stripe off the pattern) show 9 × 6, which the error names with the file.
/// (Frames that cut the board cannot tell: a part of a larger board is a usable board.)
#[test]
fn a_board_file_larger_than_the_board_is_named_with_the_likely_size() {
    let dir = tempfile::tempdir().unwrap();
    let out = run(dir.path(), &board(10, 7), &[1, 2, 3, 4, 5]);
    let se = text(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{se}");
    assert_eq!(se.lines().count(), 1, "{se}");
    assert!(se.starts_with("omni-calib-plane: error: board.json: the board file says 10 × 7"), "{se}");
    assert!(se.contains("the board is probably 9 × 6"), "{se}");
    assert!(!dir.path().join("scanner.json").exists());
}

/// The edge clearance and the lens's blur are reported with the inputs; a negative or
/// non-finite one is a usage error.
#[test]
fn the_edge_clearance_is_reported_and_a_negative_one_refused() {
    let dir = tempfile::tempdir().unwrap();
    let out = run(dir.path(), &board(9, 6), &[3, 4]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let report: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.path().join("report.json")).unwrap()).unwrap();
    assert_eq!(report["report"]["inputs"]["edge_clearance_px"], 3.0, "{report}");
    // The camera has no lens blur: the stripe detector measured it on each frame.
    assert_eq!(report["report"]["inputs"]["optics_blur_px"], serde_json::Value::Null, "{report}");
    let named =
        [("--edge-clearance-px", "-1", "--edge-clearance-px"), ("--edge-clearance-px", "nan", "--edge-clearance-px")];
    for (flag, bad, says) in named.into_iter().chain([("--optics-blur", "-1", "optics blur")]) {
        let out = Command::new(BIN)
            .current_dir(dir.path())
            .args(["fixed", "--camera", "camera.json", "--board", "board.json", flag, bad])
            .arg(frame(3))
            .output()
            .unwrap();
        let se = text(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{flag} {bad}: {se}");
        assert!(se.contains(says) && se.lines().count() == 1, "{flag} {bad}: {se}");
    }
}

/// Each frame given another frame's stripe points (a stream of the wrong frames): the plane's
/// residual RMS is 0.81 mm where the frames' own give 0.024 mm, and the frames disagree (its
/// leave-one-frame-out RMS 3 x the residual): a warning names the frames that disagree most, and
/// `--max-residual-mm` below the residual refuses the fit, writing nothing. The frames' own
/// stripes draw no such warning.
#[test]
fn frames_that_disagree_are_named_and_a_residual_above_the_limit_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let frames = [3, 4, 12, 17];
    let out = run(dir.path(), &board(9, 6), &frames);
    let se = text(&out.stderr);
    assert!(out.status.success(), "{se}");
    assert!(!se.contains("disagree"), "{se}");
    // The frames' board points, as `--points` writes them, each given to the next frame.
    let points = Command::new(BIN)
        .current_dir(dir.path())
        .args(["fixed", "--camera", "camera.json", "--board", "board.json", "--points", "points.jsonl"])
        .args(["-o", "own.json"])
        .args(frames.map(frame))
        .output()
        .unwrap();
    assert!(points.status.success(), "{}", text(&points.stderr));
    let mut by_frame: Vec<(String, Vec<String>)> = frames.iter().map(|&k| (frame(k), Vec::new())).collect();
    for line in std::fs::read_to_string(dir.path().join("points.jsonl")).unwrap().lines() {
        let p: serde_json::Value = serde_json::from_str(line).unwrap();
        let at = by_frame.iter().position(|(name, _)| p["frame"] == name.as_str()).unwrap();
        by_frame[at].1.push(format!("[{},{},100,5,0]", p["px"][0], p["px"][1]));
    }
    let mut stream = String::from("{\"type\":\"header\",\"format\":\"omniscan.stream\",\"version\":1}\n");
    for (k, (name, _)) in by_frame.iter().enumerate() {
        let other = &by_frame[(k + 1) % by_frame.len()].1;
        stream += &format!(
            "{{\"type\":\"frame\",\"seq\":{k},\"path\":{name:?},\"alpha_deg\":0,\"facet\":0,\"stripe\":[{}]}}\n",
            other.join(",")
        );
    }
    stream += "{\"type\":\"status\",\"frames\":4,\"frames_missing\":0,\"complete\":true,\"errors\":[]}\n";
    std::fs::write(dir.path().join("swapped.jsonl"), stream).unwrap();
    let swapped = |extra: &[&str]| {
        Command::new(BIN)
            .current_dir(dir.path())
            .args(["fixed", "--camera", "camera.json", "--board", "board.json", "--stripes", "swapped.jsonl"])
            .args(extra)
            .output()
            .unwrap()
    };
    let out = swapped(&["-o", "swapped.json"]);
    let se = text(&out.stderr);
    assert!(out.status.success(), "{se}");
    let warnings: Vec<&str> = se.lines().filter(|l| l.contains("the frames disagree about the plane")).collect();
    assert_eq!(warnings.len(), 1, "{se}");
    assert!(warnings[0].contains("(most: im"), "{se}");
    let out = swapped(&["--max-residual-mm", "0.5", "-o", "refused.json"]);
    let se = text(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{se}");
    let errors: Vec<&str> = se.lines().filter(|l| l.contains("error:")).collect();
    assert_eq!(errors.len(), 1, "{se}");
    assert!(
        errors[0].contains("residual RMS is") && errors[0].contains("swapped.jsonl belong to these frames"),
        "{se}"
    );
    assert!(!dir.path().join("refused.json").exists());
}

/// A border kept wider than the board's (20 mm here, where im8's stripe leaves the paper 10-15
/// mm beyond the pattern): most of im8's border points lie off the plane, tens of mm, and one
/// warning names the frame and the border kept; the robust fit leaves them out. With the real
/// border (7.5 mm), none.
#[test]
fn a_border_wider_than_the_boards_is_warned_of() {
    let dir = tempfile::tempdir().unwrap();
    let out = run_with(dir.path(), &board(9, 6), &[3, 4, 8], &["--margin-mm", "20"]);
    let se = text(&out.stderr);
    assert!(out.status.success(), "{se}");
    let warning =
        se.lines().find(|l| l.contains("on the board's border off the plane")).unwrap_or_else(|| panic!("{se}"));
    assert!(
        warning.contains("im8.png ") && !warning.contains("im4.png") && warning.contains("the 20 mm kept"),
        "{warning}"
    );
    let report: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.path().join("report.json")).unwrap()).unwrap();
    let frames = report["report"]["frames"].as_array().unwrap();
    let im8 = frames.iter().find(|f| f["name"].as_str().unwrap().ends_with("im8.png")).unwrap();
    let (border, off) = (im8["border_points"].as_u64().unwrap(), im8["border_outliers"].as_u64().unwrap());
    assert!(border >= 100 && 2 * off > border, "{im8}");
    // Beyond the paper: tens of mm behind the board's plane.
    assert!(im8["border_outlier_median_mm"].as_f64().unwrap() > 10.0, "{im8}");
    // The real border, 7.5 mm: the border points lie on the plane, no warning.
    let out = run_with(dir.path(), &board(9, 6), &[3, 4, 8], &["--margin-mm", "7.5"]);
    assert!(out.status.success() && !text(&out.stderr).contains("border off the plane"), "{}", text(&out.stderr));
}

#[test]
fn one_stripe_per_column_drops_the_reflections_on_the_border() {
    let dir = tempfile::tempdir().unwrap();
    let border_outliers = |extra: &[&str]| -> Vec<u64> {
        let out = run_with(dir.path(), &board(9, 6), &[10, 12], extra);
        assert!(out.status.success(), "{}", text(&out.stderr));
        let report: serde_json::Value =
            serde_json::from_slice(&std::fs::read(dir.path().join("report.json")).unwrap()).unwrap();
        let frames = report["report"]["frames"].as_array().unwrap().clone();
        frames.iter().map(|f| f["border_outliers"].as_u64().unwrap()).collect()
    };
    // A dim reflection of the stripe crosses the border of both frames, 3.5-7.4 mm off the
    // board's plane; the stripe itself is ten times as bright in the same columns.
    let every = border_outliers(&["--margin-mm", "7.5"]);
    assert!(every.iter().all(|&n| n >= 30), "{every:?}");
    // Measured: none left on either frame.
    let one = border_outliers(&["--margin-mm", "7.5", "--one-stripe-per", "column"]);
    assert!(one.iter().all(|&n| n <= 5), "{one:?}");
}
