//! The rig chained through the light-plane calibration: `omni-sim rig --laser-off` →
//! `omni-ridge` → `omni-calib-plane fit` on the TRUE camera and TRUE board poses must give back
//! the simulated transmitter's light planes.
//!
//! omni-ridge and omni-calib-plane are binaries of other packages, so Cargo gives this test no
//! `CARGO_BIN_EXE_` path for them; they are looked up next to this test's own executable
//! (`target/<profile>/deps/..`), where `cargo test --workspace` (or
//! `cargo build -p omni-ridge -p omni-calib-plane`) puts them. If they were not built, the test
//! says so on stderr and passes without checking anything.

use omni_formats::ScannerFile;
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};

fn ok(what: &str, out: &Output) {
    assert!(out.status.success(), "{what}: exit {:?}: {}", out.status.code(), String::from_utf8_lossy(&out.stderr));
}

/// A binary of another workspace package in this test's target directory, if built.
fn sibling_binary(name: &str) -> Option<PathBuf> {
    let exe = std::env::current_exe().ok()?;
    let profile_dir = exe.parent()?.parent()?;
    let path = profile_dir.join(format!("{name}{}", std::env::consts::EXE_SUFFIX));
    path.is_file().then_some(path)
}

fn run(bin: &Path, args: &[&str], dir: &Path) -> Output {
    Command::new(bin).args(args).current_dir(dir).stdin(Stdio::null()).output().unwrap()
}

fn testdata(rel: &str) -> String {
    PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../../testdata")).join(rel).display().to_string()
}

/// Angle (degrees) between two unit normals, ignoring their sign.
fn angle_deg(a: &omni_geom::Vector3<f64>, b: &omni_geom::Vector3<f64>) -> f64 {
    a.dot(b).abs().min(1.0).acos().to_degrees()
}

#[test]
fn rig_stripes_calibrate_the_light_planes_within_0_02_deg() {
    let (Some(ridge), Some(calib)) = (sibling_binary("omni-ridge"), sibling_binary("omni-calib-plane")) else {
        eprintln!(
            "SKIPPED rig_stripes_calibrate_the_light_planes_within_0_02_deg: omni-ridge or omni-calib-plane is not \
             built next to {:?}; run `cargo test --workspace` or `cargo build -p omni-ridge -p omni-calib-plane`",
            std::env::current_exe().unwrap().parent().unwrap().parent().unwrap()
        );
        return;
    };
    let sim = Path::new(env!("CARGO_BIN_EXE_omni-sim"));
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // A sensor whose transmitter is NOT the paper's ideal build (fit's default start), so the
    // fit has something to find: an encoder offset and facet errors. Full 1024 px: on a scaled
    // 512 px sensor the stripe is dim (peak ≈ 114/255) and the fit's normals scatter 0.014–0.023°
    // over noise seeds, too close to the limit; at 1024 px they are 0.007–0.009° (seeds 1–3).
    let sensor_args = [
        "sensor",
        "--preset",
        "paper",
        "--encoder-offset",
        "0.1",
        "--facet-errors",
        "0.03",
        "--seed",
        "5",
        "-o",
        "sensor",
    ];
    ok("omni-sim sensor", &run(sim, &sensor_args, d));
    let board = testdata("boards/board_9x6.json");
    let rig_args = [
        "rig",
        "--camera",
        "sensor/camera.json",
        "--scanner",
        "sensor/scanner.json",
        "--board",
        &board,
        "--angles",
        "15:24:1.5",
        "--laser-off",
        "--seed",
        "1",
        "--out",
        "rig",
    ];
    ok("omni-sim rig", &run(sim, &rig_args, d));
    let ridge_args = ["--camera", "sensor/camera.json", "rig/scan.jsonl", "-o", "stripes.jsonl"];
    ok("omni-ridge", &run(&ridge, &ridge_args, d));
    let fit_args = [
        "fit",
        "--camera",
        "sensor/camera.json",
        "--rig",
        "rig/rig.json",
        "--board-poses",
        "rig/board_poses.json",
        "--stripes",
        "stripes.jsonl",
        "-o",
        "scanner.json",
    ];
    let fit = run(&calib, &fit_args, d);
    ok("omni-calib-plane fit", &fit);
    eprintln!("{}", String::from_utf8_lossy(&fit.stderr).trim());

    let (_, truth) = ScannerFile::load_polygon(&d.join("sensor/scanner.json")).unwrap();
    let (_, fitted) = ScannerFile::load_polygon(&d.join("scanner.json")).unwrap();
    let nominal = omni_model::Transmitter::new(omni_model::TransmitterParams::paper()).unwrap();
    let mut worst_offset: f64 = 0.0;
    let mut worst: f64 = 0.0;
    let mut worst_nominal: f64 = 0.0;
    for alpha_deg in [15.0, 18.0, 21.0, 22.5] {
        let alpha = f64::to_radians(alpha_deg);
        let want = truth.light_plane(alpha, 0, 0).unwrap().plane;
        let got = fitted.light_plane(alpha, 0, 0).unwrap().plane;
        let start = nominal.light_plane(alpha, 0, 0).unwrap().plane;
        let err = angle_deg(&want.normal, &got.normal);
        let offset_err = (want.offset - got.offset).abs();
        eprintln!(
            "alpha {alpha_deg}°: light plane normal off by {err:.5}°, offset by {offset_err:.4} mm (ideal build: {:.5}°)",
            angle_deg(&want.normal, &start.normal)
        );
        worst = worst.max(err);
        worst_offset = worst_offset.max(offset_err);
        worst_nominal = worst_nominal.max(angle_deg(&want.normal, &start.normal));
    }
    assert!(worst_nominal > 0.05, "the true build must differ from the fit's start, got {worst_nominal}°");
    assert!(worst < 0.02, "fitted light planes off by up to {worst}° (limit 0.02°)");
    assert!(worst_offset < 0.2, "fitted light planes shifted by up to {worst_offset} mm (limit 0.2 mm)");
}
