//! The real omni-eval binary on synthetic clouds with known noise and bias.

use omni_cloud::rng::SplitMix64;
use omni_formats::ply::{Encoding, PointCloud, write_ply};
use omni_formats::scene::{SceneFile, SceneObject, Shape};
use omni_formats::write_doc;
use std::path::Path;
use std::process::{Command, Output};

#[path = "../../../tests/support/devices.rs"]
mod devices;
use devices::writes_into_devices;

const BIN: &str = env!("CARGO_BIN_EXE_omni-eval");

fn run(dir: &Path, args: &[&str]) -> Output {
    Command::new(BIN).current_dir(dir).args(args).output().unwrap()
}

fn json(out: &Output) -> serde_json::Value {
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    serde_json::from_slice(&out.stdout).unwrap()
}

/// Sphere r = 50 at (500, 0, 0) seen from the origin side, radial noise σ = 0.3 mm, bias +0.1 mm;
/// plus a plane patch x = 700 facing −x with σ = 0.2 mm; plus 30 stray points.
fn write_fixture(dir: &Path) {
    let mut rng = SplitMix64::new(3);
    let mut pts = Vec::new();
    for _ in 0..3000 {
        let (th, ph) = (std::f64::consts::PI + (rng.uniform() - 0.5) * 2.0, (rng.uniform() - 0.5) * 1.6);
        let r = 50.0 + 0.1 + rng.normal() * 0.3;
        pts.push([500.0 + r * th.cos() * ph.cos(), r * th.sin() * ph.cos(), r * ph.sin()]);
    }
    for _ in 0..2000 {
        pts.push([700.0 - rng.normal() * 0.2, 150.0 + rng.uniform() * 100.0, rng.uniform() * 100.0 - 50.0]);
    }
    for i in 0..30 {
        pts.push([300.0 + i as f64, -300.0, 200.0]);
    }
    let cloud = PointCloud { positions: pts, scalars: vec![] };
    write_ply(&dir.join("c.ply"), &cloud, Encoding::BinaryLittleEndian).unwrap();
    let scene = SceneFile::new(vec![
        SceneObject::new(Shape::Sphere { centre_mm: [500.0, 0.0, 0.0], radius_mm: 50.0 }).named("ball"),
        SceneObject::new(Shape::Rectangle {
            centre_mm: [700.0, 200.0, 0.0],
            normal: [-1.0, 0.0, 0.0],
            up: [0.0, 0.0, 1.0],
            width_mm: 200.0,
            height_mm: 200.0,
        })
        .named("wall"),
    ]);
    write_doc(&dir.join("scene.json"), &scene).unwrap();
}

#[test]
fn fit_reports_radius_centre_and_residuals() {
    let dir = tempfile::tempdir().unwrap();
    write_fixture(dir.path());
    let v = json(&run(
        dir.path(),
        &[
            "fit",
            "--shape",
            "sphere",
            "--crop",
            "400,-100,-100,600,100,100",
            "--radius",
            "50",
            "--centre",
            "500,0,0",
            "--json",
            "c.ply",
        ],
    ));
    let r = v["radius_error_mm"].as_f64().unwrap();
    assert!((r - 0.1).abs() < 0.05, "radius error {r}");
    assert!(v["centre_error_mm"].as_f64().unwrap() < 0.1);
    let std = v["errors"]["std_dev"].as_f64().unwrap();
    assert!((std - 0.3).abs() < 0.02, "σ {std}");
    assert!(v["errors"]["mean"].as_f64().unwrap().abs() < 0.02);
    let v =
        json(&run(dir.path(), &["fit", "--shape", "plane", "--crop", "650,100,-100,750,300,100", "--json", "c.ply"]));
    assert!((v["errors"]["std_dev"].as_f64().unwrap() - 0.2).abs() < 0.02);
    assert_eq!(v["inliers"].as_u64(), Some(2000));
    // The radius's and centre's standard errors: 3000 points of σ 0.3 mm over a cap of ±57° × ±46°
    // leave a radius of about ±0.02 mm; the jackknife says so within a factor of 3.
    let r_se = v_sphere_se(&v_sphere(dir.path()));
    assert!((0.005..=0.06).contains(&r_se), "radius error ± {r_se}");
    // The table form names the measures.
    let out = run(dir.path(), &["fit", "--shape", "sphere", "--crop", "400,-100,-100,600,100,100", "c.ply"]);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.contains("mean signed error") && text.contains("standard deviation"), "{text}");
}

fn v_sphere(dir: &Path) -> serde_json::Value {
    let args = ["fit", "--shape", "sphere", "--crop", "400,-100,-100,600,100,100", "--radius", "50", "--json", "c.ply"];
    json(&run(dir, &args))
}

fn v_sphere_se(v: &serde_json::Value) -> f64 {
    v["radius_error_se_mm"].as_f64().unwrap_or_else(|| panic!("no standard error: {v}"))
}

/// The statistics take the scatter whole, however wide beside --inlier-mm (2 mm): a plane of σ
/// 0.25-8 mm reads σ within 4 %, where statistics over the RANSAC inliers alone read at most
/// 2/√3 mm; 1 % gross outliers stay out.
#[test]
fn the_fit_statistics_follow_any_scatter() {
    let dir = tempfile::tempdir().unwrap();
    for sigma in [0.25, 4.0, 8.0] {
        let mut rng = SplitMix64::new(11);
        let mut pts: Vec<[f64; 3]> = (0..3000)
            .map(|_| [500.0 + sigma * rng.normal(), 400.0 * rng.uniform() - 200.0, 300.0 * rng.uniform() - 150.0])
            .collect();
        pts.extend((0..30).map(|k| [800.0 + k as f64, 0.0, 0.0]));
        let cloud = PointCloud { positions: pts, scalars: vec![] };
        write_ply(&dir.path().join("p.ply"), &cloud, Encoding::BinaryLittleEndian).unwrap();
        let v = json(&run(dir.path(), &["fit", "--shape", "plane", "--json", "p.ply"]));
        let std = v["errors"]["std_dev"].as_f64().unwrap();
        assert!((std / sigma - 1.0).abs() < 0.04, "σ {sigma}: read {std}");
        assert!(v["errors"]["max_abs"].as_f64().unwrap() < 5.0 * sigma.max(0.5), "{v}");
        assert!(v["band_mm"].as_f64().unwrap() >= 2.0, "{v}");
    }
}

/// A scene object without a point near it is named (a warning, a table row, the JSON's
/// `unmeasured`), not left out as if the scene had no such object.
#[test]
fn an_object_without_points_is_named_as_not_measured() {
    let dir = tempfile::tempdir().unwrap();
    write_fixture(dir.path());
    let mut scene: SceneFile = omni_formats::read_doc(&dir.path().join("scene.json")).unwrap();
    scene
        .objects
        .push(SceneObject::new(Shape::Sphere { centre_mm: [0.0, 900.0, 0.0], radius_mm: 40.0 }).named("far_ball"));
    write_doc(&dir.path().join("scene3.json"), &scene).unwrap();
    let out = run(dir.path(), &["compare", "--scene", "scene3.json", "--json", "c.ply"]);
    assert!(String::from_utf8_lossy(&out.stderr).contains("far_ball: not measured"), "{out:?}");
    let v = json(&out);
    assert_eq!(v["unmeasured"], serde_json::json!(["far_ball"]));
    assert_eq!(v["objects"].as_array().unwrap().len(), 2);
    let ball = &v["objects"][0];
    assert!(ball["radius_error_se_mm"].as_f64().unwrap() > 0.0 && ball["centre_error_se_mm"].as_f64().is_some());
    let table = run(dir.path(), &["compare", "--scene", "scene3.json", "c.ply"]);
    let text = String::from_utf8_lossy(&table.stdout);
    assert!(text.lines().any(|l| l.starts_with("far_ball") && l.contains("not measured")), "{text}");
}

#[test]
fn compare_measures_bias_and_noise_per_object() {
    let dir = tempfile::tempdir().unwrap();
    write_fixture(dir.path());
    let v = json(&run(dir.path(), &["compare", "--scene", "scene.json", "--json", "c.ply"]));
    assert_eq!(v["stray_points"].as_u64(), Some(30));
    let objects = v["objects"].as_array().unwrap();
    let ball = objects.iter().find(|o| o["name"] == "ball").unwrap();
    let mean = ball["errors"]["mean"].as_f64().unwrap();
    let std = ball["errors"]["std_dev"].as_f64().unwrap();
    assert!((mean - 0.1).abs() < 0.02 && (std - 0.3).abs() < 0.02, "{mean} {std}");
    assert!((ball["radius_error_mm"].as_f64().unwrap() - 0.1).abs() < 0.05);
    let wall = objects.iter().find(|o| o["name"] == "wall").unwrap();
    assert!((wall["errors"]["std_dev"].as_f64().unwrap() - 0.2).abs() < 0.02);
    assert_eq!(wall["errors"]["count"].as_u64(), Some(2000));
    let out = run(dir.path(), &["compare", "--scene", "scene.json", "c.ply"]);
    assert!(String::from_utf8_lossy(&out.stdout).contains("ball"));
}

#[test]
fn bad_inputs() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    write_fixture(d);
    std::fs::write(
        d.join("empty.ply"),
        "ply\nformat ascii 1.0\nelement vertex 0\nproperty float x\nproperty float y\nproperty float z\nend_header\n",
    )
    .unwrap();
    let out = run(d, &["fit", "--shape", "plane", "empty.ply"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.code() == Some(1) && err.contains("empty.ply") && err.contains("no vertices"), "{err}");
    std::fs::write(d.join("bad.json"), "{\"format\":\"omniscan.scene\",\"version\":1}").unwrap();
    let out = run(d, &["compare", "--scene", "bad.json", "c.ply"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.code() == Some(1) && err.contains("bad.json") && err.contains("objects"), "{err}");
    assert_eq!(run(d, &["fit", "--shape", "torus", "c.ply"]).status.code(), Some(2));
    assert_eq!(run(d, &["fit", "--shape", "plane", "--crop", "1,2", "c.ply"]).status.code(), Some(2));
    let out = run(d, &["fit", "--shape", "sphere", "--crop", "0,0,0,1,1,1", "c.ply"]);
    assert_eq!(out.status.code(), Some(1));
    // Numbers that cannot be a threshold, a radius or a count are usage errors naming the option.
    let usage: [&[&str]; 5] = [
        &["fit", "--shape", "sphere", "--radius", "NaN", "c.ply"],
        &["fit", "--shape", "plane", "--iterations", "0", "c.ply"],
        &["fit", "--shape", "plane", "--inlier-mm", "-1", "c.ply"],
        &["compare", "--scene", "bad.json", "--max-distance-mm", "NaN", "c.ply"],
        &["compare", "--scene", "bad.json", "--inlier-mm", "0", "c.ply"],
    ];
    for args in usage {
        let out = run(d, args);
        let err = String::from_utf8_lossy(&out.stderr);
        let option = args.iter().find(|a| a.starts_with("--") && **a != "--shape" && **a != "--scene").unwrap();
        assert!(out.status.code() == Some(2) && err.contains(option), "{args:?}: {err}");
    }
}

#[test]
fn fits_a_cone() {
    let dir = tempfile::tempdir().unwrap();
    let mut rng = SplitMix64::new(9);
    // Cone: apex (450, -120, 100), axis down, half-angle atan(60/200) (the bench cone), σ 0.2 mm.
    let th = (60.0f64 / 200.0).atan();
    let pts: Vec<[f64; 3]> = (0..3000)
        .map(|_| {
            let h = 20.0 + rng.uniform() * 170.0;
            let phi = 2.0 + rng.uniform() * 2.5; // the side facing the sensor (−x)
            let e = rng.normal() * 0.2;
            let r = h * th.tan() + e / th.cos();
            [450.0 + r * phi.cos(), -120.0 + r * phi.sin(), 100.0 - h]
        })
        .collect();
    write_ply(&dir.path().join("cone.ply"), &PointCloud { positions: pts, scalars: vec![] }, Encoding::Ascii).unwrap();
    let v = json(&run(dir.path(), &["fit", "--shape", "cone", "--json", "cone.ply"]));
    let half = v["shape"]["half_angle_deg"].as_f64().unwrap();
    assert!((half - th.to_degrees()).abs() < 0.2, "half-angle {half}°");
    let apex = v["shape"]["apex_mm"].as_array().unwrap();
    assert!((apex[2].as_f64().unwrap() - 100.0).abs() < 1.5, "{apex:?}");
    assert!((v["errors"]["std_dev"].as_f64().unwrap() - 0.2).abs() < 0.03);
}

#[test]
fn render_into_dev_null_and_a_fifo() {
    let dir = tempfile::tempdir().unwrap();
    write_fixture(dir.path());
    let png = writes_into_devices(dir.path(), |o| run(dir.path(), &["render", "c.ply", "-o", o, "--width", "64"]));
    assert!(png.starts_with(b"\x89PNG"));
}

/// Runs with stdout a pipe whose reading end is already closed (`| head -1` that has quit).
fn run_into_closed_pipe(dir: &Path, args: &[&str]) -> Output {
    let (reader, writer) = std::io::pipe().unwrap();
    drop(reader);
    Command::new(BIN).current_dir(dir).args(args).stdout(writer).stderr(std::process::Stdio::piped()).output().unwrap()
}

#[test]
fn fit_and_compare_exit_cleanly_when_stdout_closes() {
    let dir = tempfile::tempdir().unwrap();
    write_fixture(dir.path());
    for args in [
        &["fit", "--shape", "sphere", "--crop", "400,-100,-100,600,100,100", "c.ply"][..],
        &["fit", "--shape", "sphere", "--crop", "400,-100,-100,600,100,100", "--json", "c.ply"],
        &["compare", "--scene", "scene.json", "c.ply"],
        &["compare", "--scene", "scene.json", "--json", "c.ply"],
    ] {
        let out = run_into_closed_pipe(dir.path(), args);
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(0), "{args:?}: {err}");
        assert!(!err.contains("panicked"), "{err}");
    }
}

#[test]
fn render_sizes_are_bounded_and_errors_name_the_output_once() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    write_fixture(d);
    for w in ["0", "2000000000", "-5"] {
        let out = run(d, &["render", "c.ply", "-o", "p.png", "--width", w]);
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "--width {w}: {err}");
        assert!(err.contains("--width") && !err.contains("panicked"), "{err}");
        assert!(!d.join("p.png").exists());
    }
    let out = run(d, &["render", "c.ply", "-o", "nodir/p.png"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert_eq!(err.matches("nodir/p.png").count(), 1, "{err}");
}

#[test]
fn a_scene_rectangle_of_negative_width_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    write_fixture(d);
    let text =
        std::fs::read_to_string(d.join("scene.json")).unwrap().replace("\"width_mm\": 200.0", "\"width_mm\": -200.0");
    assert!(text.contains("-200"));
    std::fs::write(d.join("neg.json"), text).unwrap();
    let out = run(d, &["compare", "--scene", "neg.json", "c.ply"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(err.contains("neg.json") && err.contains("\"wall\"") && err.contains("width_mm"), "{err}");
}

/// `budget` needs the polygon's laser source for its photometry: a fixed-plane scanner.json is
/// refused in one line naming the kind.
#[test]
fn budget_refuses_a_fixed_plane_scanner_naming_the_kind() {
    let dir = tempfile::tempdir().unwrap();
    let camera = r#"{"format": "omniscan.camera", "version": 1, "model": {"kind": "mei", "xi": 1.0,
        "fx_px": 300, "fy_px": 300, "cx_px": 255.5, "cy_px": 255.5, "width": 512, "height": 512}}"#;
    std::fs::write(dir.path().join("camera.json"), camera).unwrap();
    let scanner = r#"{"format": "omniscan.scanner", "version": 2, "transmitter": {"kind": "fixed_planes",
        "planes": [{"laser": 0, "normal": [1, 0, 0], "distance_mm": 300}]}}"#;
    std::fs::write(dir.path().join("scanner.json"), scanner).unwrap();
    let out = run(dir.path(), &["budget", "--camera", "camera.json", "--scanner", "scanner.json"]);
    assert_eq!(out.status.code(), Some(1));
    assert_eq!(
        String::from_utf8_lossy(&out.stderr),
        "omni-eval: error: scanner.json: field transmitter.kind: transmitter kind \"fixed_planes\" cannot be used here: this needs kind \"polygon\" (the rotating polygon mirror)\n"
    );
}

/// A directory holding the paper sensor's camera.json and scanner.json.
fn paper_sensor_files() -> tempfile::TempDir {
    let dir = tempfile::tempdir().unwrap();
    let camera =
        omni_formats::CameraFile::new(omni_formats::CameraSpec::Hyperbolic(omni_model::HyperbolicParams::paper()));
    omni_formats::write_doc(&dir.path().join("camera.json"), &camera).unwrap();
    let scanner = omni_formats::ScannerFile::new(omni_model::TransmitterParams::paper());
    omni_formats::write_doc(&dir.path().join("scanner.json"), &scanner).unwrap();
    dir
}

/// A table that cannot be written (a full disk behind `>`) fails naming stdout.
#[test]
fn a_full_stdout_is_an_error_naming_it() {
    let dir = paper_sensor_files();
    let full = std::fs::OpenOptions::new().write(true).open("/dev/full").unwrap();
    let out = Command::new(BIN)
        .current_dir(dir.path())
        .args(["budget", "--camera", "camera.json", "--scanner", "scanner.json"])
        .stdout(full)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert_eq!(err.lines().count(), 1, "{err}");
    assert!(err.contains("stdout: No space left on device"), "{err}");
}

/// An angle the polygon's facet cannot reach, a range at 0 mm and 10 000 of them are usage
/// errors that say which, not a table.
#[test]
fn budget_refuses_angles_outside_the_facet_and_ranges_it_cannot_take() {
    let dir = paper_sensor_files();
    for alpha in ["200", "1e9", "-20"] {
        let args = ["budget", "--camera", "camera.json", "--scanner", "scanner.json", "--alpha-deg", alpha];
        let out = run(dir.path(), &args);
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{alpha}: {err}");
        assert!(err.contains("is far outside the facet's range [0, 30°)") && err.lines().count() == 1, "{err}");
        assert!(out.stdout.is_empty(), "{alpha}: a table was printed");
    }
    for (range, says) in [
        ("0:10:1", "ranges are positive distances (mm), got 0"),
        ("300:2000:0.0001", "more than 10000 ranges"),
        ("300:x:10", "expected start:stop:step or a,b,c (mm)"),
    ] {
        let out =
            run(dir.path(), &["budget", "--camera", "camera.json", "--scanner", "scanner.json", "--range", range]);
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{range}: {err}");
        assert!(err.contains(says) && err.lines().count() == 1, "{range}: {err}");
    }
}
