//! The end-to-end demo (issue 9) at reduced size: scripts/demo.sh with DEMO_SIZE=small runs the
//! whole chain — imperfect virtual sensor, calibration through the scripts, scans through the
//! emulator and the real binaries in pipes, evaluation — and its table is checked against the
//! targets. Needs every omni-* binary, which `cargo test --workspace` builds next to this test.

use std::path::PathBuf;
use std::process::Command;

fn bin_dir() -> PathBuf {
    // target/<profile>/deps/demo-… → target/<profile>
    let exe = std::env::current_exe().unwrap();
    exe.parent().and_then(|d| d.parent()).unwrap().to_path_buf()
}

fn metric(table: &serde_json::Value, obj: &str, sensor: &str, key: &str) -> f64 {
    table[obj][sensor][key].as_f64().unwrap_or_else(|| panic!("{obj}/{sensor}/{key} missing in {table}"))
}

#[test]
fn reduced_demo_meets_the_targets() {
    let bins = bin_dir();
    for tool in [
        "omni-sim",
        "omni-trigger",
        "omni-ridge",
        "omni-calib-receiver",
        "omni-calib-plane",
        "omni-triangulate",
        "omni-merge",
    ] {
        assert!(bins.join(tool).exists(), "{tool} not built in {} (run `cargo test --workspace`)", bins.display());
    }
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..");
    let out = tempfile::tempdir().unwrap();
    let status = Command::new("bash")
        .arg(root.join("scripts/demo.sh"))
        .env("OUT", out.path())
        .env("BIN", &bins)
        .env("DEMO_SIZE", "small")
        .status()
        .unwrap();
    assert!(status.success(), "demo.sh failed");
    let table: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.path().join("table.json")).unwrap()).unwrap();
    // The realistic sensor (speckle, its lens, a mid-bright room): the measured σ must be what
    // the error budget predicts at 500 mm, within a factor; the calibration must cost little.
    let budget = table["budget_500mm"]["total_mm"].as_f64().expect("budget in table.json");
    assert!(budget > 0.05 && budget < 2.0, "budget {budget}");
    for obj in ["plane", "cylinder", "sphere"] {
        let fit_cal = metric(&table, obj, "calibrated", "sigma_fit_mm");
        let fit_true = metric(&table, obj, "true files", "sigma_fit_mm");
        let truth_cal = metric(&table, obj, "calibrated", "sigma_truth_mm");
        let mean_cal = metric(&table, obj, "calibrated", "mean_mm");
        eprintln!(
            "{obj}: σ fit {fit_cal:.3} (true files {fit_true:.3}), σ vs truth {truth_cal:.3}, mean {mean_cal:+.3} mm, \
             budget {budget:.3}"
        );
        assert!(fit_cal <= 1.5 * budget, "{obj}: σ {fit_cal} > 1.5 × budget {budget}");
        assert!(truth_cal <= 1.5 * budget, "{obj}: σ vs truth {truth_cal} > 1.5 × budget {budget}");
        assert!(fit_cal <= 1.25 * fit_true, "{obj}: calibration costs too much: {fit_cal} vs {fit_true}");
        // The calibrated light planes leave the plane +0.116 mm off (true files +0.015 mm).
        assert!(mean_cal.abs() <= 0.15, "{obj}: mean {mean_cal}");
        // Enough points for the fits (the reduced scan's 15 frames, with laser-off frames, gave
        // the sphere 131, the cylinder 404 and the plane 2110 under speckle).
        assert!(metric(&table, obj, "calibrated", "points") > 40.0, "{obj}: too few points");
    }
    // The plane's σ is the budget's own case: within a factor 1.5 of it both ways.
    let plane = metric(&table, "plane", "calibrated", "sigma_fit_mm");
    assert!(plane >= budget / 1.5, "plane σ {plane} far below the budget {budget}: the budget is wrong");
    // Fitted radii: the reduced scan's 100–400 points on a 50 mm radius fix them only to a
    // standard error of 0.1–0.2 mm, which the fit reports. Over six emulator seeds (the same
    // calibration) the calibrated sensor's errors ran −0.34…+0.04 mm on the cylinder (mean
    // −0.15) and −0.42…−0.08 on the sphere (mean −0.25, its standard error 0.05): the sphere
    // comes out small, and `make demo`'s 0.1 mm is missed (docs/DECISIONS.md). Asserted: within
    // 0.25 mm plus three standard errors.
    for obj in ["cylinder", "sphere"] {
        for sensor in ["calibrated", "true files"] {
            let radius_error = metric(&table, obj, sensor, "radius_error_mm");
            let se = metric(&table, obj, sensor, "radius_error_se_mm");
            eprintln!("{obj} ({sensor}): fitted radius error {radius_error:+.3} mm (standard error {se:.3})");
            assert!(se > 0.0 && se < 0.3, "{obj} ({sensor}): radius standard error {se}");
            assert!(radius_error.abs() <= 0.25 + 3.0 * se, "{obj} ({sensor}): radius error {radius_error}, se {se}");
        }
    }
    // The plane misses its target (half the paper's σ, speckle-limited): the table scales its σ
    // by the budget over the apertures, through its own value at the camera's F/4, falling with
    // the aperture's diameter.
    let sweep = &table["plane"]["calibrated"]["f_number_sweep"];
    let at = |f: &str| sweep[f].as_f64().unwrap_or_else(|| panic!("{f} missing in the plane's sweep {sweep}"));
    assert!((at("F/4") - plane).abs() < 1e-9, "sweep {sweep} vs σ {plane}");
    let stops = ["F/1.4", "F/2", "F/2.8", "F/4", "F/5.6", "F/8", "F/11"];
    assert!(stops.windows(2).all(|w| at(w[0]) < at(w[1])), "sweep not rising with the F-number: {sweep}");
    // No aperture alone meets it (speckle sets the limit); the table names the optics that do:
    // a speckle reducer's patterns and the F-number, with the σ the budget scales to.
    let reducer = &table["plane"]["calibrated"]["speckle_reducer"];
    let reduced = reducer["sigma_fit_mm"].as_f64().unwrap_or_else(|| panic!("no speckle reducer named: {reducer}"));
    assert!(reduced <= 0.245 && reduced < plane, "speckle reducer {reducer}");
    assert!(reducer["patterns"].as_u64().is_some_and(|n| (4..=16).contains(&n)), "{reducer}");
    // And the plane scanned again through it (the true camera's optics changed, the calibration
    // kept): the rendered σ is the prediction's (0.242 against 0.240 mm when written), far below
    // the camera's own.
    let rendered = reducer["rendered_sigma_fit_mm"].as_f64().unwrap_or_else(|| panic!("not rendered: {reducer}"));
    eprintln!("plane through the speckle reducer: σ fit {rendered:.3} mm, predicted {reduced:.3} mm");
    assert!((rendered / reduced - 1.0).abs() <= 0.15, "rendered {rendered} against the prediction {reduced}");
    assert!(rendered <= 0.6 * plane, "rendered {rendered} against {plane} at the camera's optics");
    assert!(reducer["rendered_points"].as_u64().is_some_and(|n| n > 1000), "{reducer}");
    for obj in ["plane", "cylinder", "sphere"] {
        assert!(out.path().join(obj).join("cloud.png").exists());
    }
}
