//! The real binary on a small exact stream made with the paper sensor models.

use omni_formats::stream::{Frame, Record, StreamReader, StreamWriter, StripePoint};
use omni_formats::{CameraFile, CameraSpec, ScannerFile, write_doc};
use omni_geom::Point3;
use omni_model::{CameraModel, HyperbolicCamera, HyperbolicParams, Transmitter, TransmitterParams};
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

#[path = "../../../tests/support/devices.rs"]
mod devices;
use devices::writes_into_devices;

const BIN: &str = env!("CARGO_BIN_EXE_omni-triangulate");

struct Fixture {
    dir: tempfile::TempDir,
    truth: Vec<Vec<Point3<f64>>>,
}

impl Fixture {
    fn path(&self, name: &str) -> PathBuf {
        self.dir.path().join(name)
    }
}

/// camera.json, scanner.json and a 3-frame stripe stream whose pixels are exact projections of
/// lit points on laser 0's light plane.
fn fixture() -> Fixture {
    let dir = tempfile::tempdir().unwrap();
    write_doc(&dir.path().join("camera.json"), &CameraFile::new(CameraSpec::Hyperbolic(HyperbolicParams::paper())))
        .unwrap();
    write_doc(&dir.path().join("scanner.json"), &ScannerFile::new(TransmitterParams::paper())).unwrap();
    let cam = HyperbolicCamera::new(HyperbolicParams::paper()).unwrap();
    let tx = Transmitter::new(TransmitterParams::paper()).unwrap();
    let mut truth = Vec::new();
    let mut text = Vec::new();
    {
        let mut w = StreamWriter::new(&mut text, "mem");
        w.write(&Record::Header(omni_formats::stream::Header::new("test"))).unwrap();
        for (seq, alpha) in [(0u64, 5.0f64), (1, 15.0), (2, 25.0)] {
            let lp = tx.light_plane(alpha.to_radians(), 0, 0).unwrap();
            let across = lp.plane.normal.cross(&lp.out_dir).normalize();
            let mut f = Frame::new(seq, format!("{seq}.png"), alpha, 0);
            let mut stripe = Vec::new();
            let mut pts = Vec::new();
            for i in 0..10 {
                let p = lp.facet_point
                    + lp.out_dir.into_inner() * (400.0 + 60.0 * i as f64)
                    + across * (i as f64 * 30.0 - 150.0);
                let px = cam.point_to_pixel(&p).unwrap();
                stripe.push(StripePoint { u: px.x, v: px.y, intensity: 100.0 + i as f64, width: 3.0, quality: 0 });
                pts.push(p);
            }
            f.stripe = Some(stripe);
            f.extra.insert("exposure_us".into(), 500.into());
            w.write(&Record::Frame(Box::new(f))).unwrap();
            truth.push(pts);
        }
        w.write(&Record::Status(omni_formats::stream::Status::complete(3))).unwrap();
    }
    std::fs::write(dir.path().join("ridges.jsonl"), text).unwrap();
    Fixture { dir, truth }
}

/// A stream's header line.
const HEADER: &str = "{\"type\":\"header\",\"format\":\"omniscan.stream\",\"version\":1}\n";

fn run(dir: &Path, args: &[&str]) -> Output {
    Command::new(BIN).current_dir(dir).args(args).output().unwrap()
}

#[test]
fn writes_the_stream_with_points_and_keeps_other_fields() {
    let fx = fixture();
    let out = run(fx.dir.path(), &["--camera", "camera.json", "--scanner", "scanner.json", "ridges.jsonl"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let records: Vec<Record> = StreamReader::new(out.stdout.as_slice(), "out").map(|r| r.unwrap()).collect();
    let Record::Header(h) = &records[0] else { panic!("no header") };
    assert_eq!(h.producers.len(), 2);
    assert!(h.producers[1].starts_with("omni-triangulate"));
    let mut n = 0;
    let Some(Record::Status(status)) = records.last() else { panic!("no status record") };
    assert_eq!(status.extra["triangulate"]["points"], 30);
    assert_eq!(status.extra["triangulate"]["grazing"], 0);
    for (r, truth) in records[1..4].iter().zip(&fx.truth) {
        let Record::Frame(f) = r else { panic!() };
        assert_eq!(f.extra.get("exposure_us"), Some(&500.into()));
        let pts = f.points.as_ref().unwrap();
        assert_eq!(pts.len(), truth.len());
        for p in pts {
            assert!((Point3::from(p.xyz) - truth[p.stripe_index as usize]).norm() < 1e-9);
            assert_eq!(p.laser, 0);
            n += 1;
        }
    }
    assert_eq!(n, 30);
}

#[test]
fn writes_ply_with_scalar_fields() {
    let fx = fixture();
    let out =
        run(fx.dir.path(), &["--camera", "camera.json", "--scanner", "scanner.json", "ridges.jsonl", "-o", "c.ply"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert!(out.stdout.is_empty());
    let cloud = omni_formats::ply::read_ply(&fx.path("c.ply")).unwrap();
    assert_eq!(cloud.len(), 30);
    for name in
        ["intensity", "scalar_frame", "scalar_laser", "scalar_alpha_deg", "scalar_range", "scalar_u", "scalar_v"]
    {
        assert!(cloud.scalar(name).is_some(), "{name}");
    }
    assert_eq!(cloud.scalar("scalar_alpha_deg").unwrap()[29], 25.0);
    assert_eq!(cloud.scalar("intensity").unwrap()[11], 101.0);
    // Float PLY: positions to float precision.
    let p = cloud.positions[0];
    assert!((Point3::from(p) - fx.truth[0][0]).norm() < 1e-3);
    // The fixture's stripes are straight lines 10 points long: 4 nearest neighbours lie on one.
    let args = ["--camera", "camera.json", "--scanner", "scanner.json", "ridges.jsonl", "-o", "n.ply", "--normals"];
    let args = [&args[..], &["--normal-neighbours", "4"]].concat();
    let out = run(fx.dir.path(), &args);
    let se = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{se}");
    assert!(se.contains("nearest neighbours lie along a line (one stripe)"), "{se}");
}

#[test]
fn bad_input_fails_with_one_line_and_leaves_no_output() {
    let fx = fixture();
    let frame_without_stripe = "{\"type\":\"frame\",\"seq\":7,\"path\":\"a.png\",\"alpha_deg\":3,\"facet\":0}\n";
    std::fs::write(fx.path("nostripe.jsonl"), format!("{HEADER}{frame_without_stripe}")).unwrap();
    let nan =
        "{\"type\":\"frame\",\"seq\":1,\"path\":\"a.png\",\"alpha_deg\":3,\"facet\":0,\"stripe\":[[NaN,1,1,1,0]]}\n";
    std::fs::write(fx.path("nan.jsonl"), format!("{HEADER}{nan}")).unwrap();
    // A stream is its header first: frames alone are refused.
    std::fs::write(fx.path("headless.jsonl"), frame_without_stripe).unwrap();
    // What a failed tool upstream leaves: nothing.
    std::fs::write(fx.path("empty.jsonl"), "").unwrap();
    // Pixels no ray of this camera passes through (the frames of another camera).
    let elsewhere = "{\"type\":\"frame\",\"seq\":1,\"path\":\"a.png\",\"alpha_deg\":3,\"facet\":0,\"stripe\":[[5000,5000,1,1,0]]}\n";
    let status = "{\"type\":\"status\",\"frames\":1,\"frames_missing\":0,\"complete\":true,\"errors\":[]}\n";
    std::fs::write(fx.path("elsewhere.jsonl"), format!("{HEADER}{elsewhere}{status}")).unwrap();
    // The stripes of the same sensor's 512 px frames read with its 1024 px camera: every pixel
    // has a ray, none a lit point.
    let halved: Vec<String> = std::fs::read_to_string(fx.path("ridges.jsonl"))
        .unwrap()
        .lines()
        .map(|line| {
            let mut record: serde_json::Value = serde_json::from_str(line).unwrap();
            for p in record.get_mut("stripe").and_then(|s| s.as_array_mut()).into_iter().flatten() {
                for k in 0..2 {
                    p[k] = ((p[k].as_f64().unwrap() + 0.5) / 2.0 - 0.5).into();
                }
            }
            record.to_string()
        })
        .collect();
    std::fs::write(fx.path("ridges512.jsonl"), halved.join("\n") + "\n").unwrap();
    for (input, expect) in [
        ("empty.jsonl", "empty stream"),
        ("elsewhere.jsonl", "none of its 1 stripe pixels maps to a ray of camera.json"),
        ("nostripe.jsonl", "frame 7"),
        ("nan.jsonl", "line 2"),
        ("missing.jsonl", "missing.jsonl"),
        ("headless.jsonl", "line 1: the stream starts with a frame record, not its header"),
    ] {
        let out = run(
            fx.dir.path(),
            &["--camera", "camera.json", "--scanner", "scanner.json", input, "-o", "out.jsonl", "--ply", "c.ply"],
        );
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{err}");
        assert!(err.contains(input) && err.contains(expect) && err.lines().count() == 1, "{err}");
        assert!(!fx.path("out.jsonl").exists() && !fx.path("c.ply").exists());
    }
    let out = run(
        fx.dir.path(),
        &[
            "--camera",
            "camera.json",
            "--scanner",
            "scanner.json",
            "ridges512.jsonl",
            "-o",
            "out.jsonl",
            "--ply",
            "c.ply",
        ],
    );
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(err.contains("none of its 30 stripe pixels gives a point") && err.lines().count() == 1, "{err}");
    assert!(!fx.path("out.jsonl").exists() && !fx.path("c.ply").exists());
    let out = run(fx.dir.path(), &["--camera", "nope.json", "--scanner", "scanner.json", "ridges.jsonl"]);
    assert_eq!(out.status.code(), Some(1));
    let out =
        run(fx.dir.path(), &["--camera", "camera.json", "--scanner", "scanner.json", "--min-incidence-deg", "95"]);
    assert_eq!(out.status.code(), Some(2));
    let out = run(fx.dir.path(), &["--bogus"]);
    assert_eq!(out.status.code(), Some(2));
    let out = run(fx.dir.path(), &["--help"]);
    assert!(out.status.success() && String::from_utf8_lossy(&out.stdout).contains("Examples"));
}

#[test]
fn dev_null_and_fifo_outputs_stay_what_they_are() {
    let fx = fixture();
    let d = fx.dir.path();
    let text = writes_into_devices(d, |o| {
        run(d, &["--camera", "camera.json", "--scanner", "scanner.json", "ridges.jsonl", "-o", o])
    });
    let records: Vec<Record> = StreamReader::new(text.as_slice(), "fifo").map(|r| r.unwrap()).collect();
    assert_eq!(records.len(), 5);
    let out = run(d, &["--camera", "camera.json", "--scanner", "scanner.json", "ridges.jsonl", "--ply", "/dev/null"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert!(std::os::unix::fs::FileTypeExt::is_char_device(&std::fs::metadata("/dev/null").unwrap().file_type()));
}

#[test]
fn facets_off_the_polygon_and_angles_far_outside_the_facet_are_refused() {
    let fx = fixture();
    let d = fx.dir.path();
    let frame = |alpha: &str, facet: &str| {
        format!(
            "{{\"type\":\"frame\",\"seq\":4,\"path\":\"a.png\",\"alpha_deg\":{alpha},\"facet\":{facet},\"lasers\":[0],\"stripe\":[[500,500,1,1,0]]}}\n"
        )
    };
    for (name, text, expect) in
        [("facet.jsonl", frame("15", "12"), "field facet"), ("alpha.jsonl", frame("95", "0"), "field alpha_deg")]
    {
        std::fs::write(d.join(name), format!("{HEADER}{text}")).unwrap();
        let out = run(d, &["--camera", "camera.json", "--scanner", "scanner.json", name, "-o", "out.jsonl"]);
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{err}");
        assert!(err.contains(name) && err.contains("frame 4") && err.contains(expect), "{err}");
        assert!(!d.join("out.jsonl").exists());
    }
}

/// A scanner file whose calibration never saw facet 3 (its report's `model.fixed`): points lit
/// off facet 3 are triangulated through its initial plane, with one warning naming the file and
/// the facet; others bring none. Laser 0 reflects off the frame's facet, laser 1 off the
/// opposite one (offset 6): laser 1's points in a frame on facet 9 come off facet 3.
#[test]
fn frames_on_facets_the_calibration_never_saw_are_warned_of() {
    let fx = fixture();
    let d = fx.dir.path();
    let mut scanner = ScannerFile::new(TransmitterParams::paper());
    scanner.report = Some(serde_json::json!({"model": {"fixed": [
        "facet_errors[3]: facet not observed, kept at its initial value",
        "polygon.circumradius_mm: nominal (radius errors are fitted per facet)"
    ]}}));
    write_doc(&d.join("partial.json"), &scanner).unwrap();
    let cam = HyperbolicCamera::new(HyperbolicParams::paper()).unwrap();
    let tx = Transmitter::new(TransmitterParams::paper()).unwrap();
    // Three frames of one laser's stripe, each frame on `facet`.
    let stream = |facet: u32, laser: u32| {
        let mut text = Vec::new();
        let mut w = StreamWriter::new(&mut text, "mem");
        w.write(&Record::Header(omni_formats::stream::Header::new("test"))).unwrap();
        for (seq, alpha) in [(0u64, 5.0f64), (1, 15.0), (2, 25.0)] {
            let lp = tx.light_plane(alpha.to_radians(), facet, laser as usize).unwrap();
            let across = lp.plane.normal.cross(&lp.out_dir).normalize();
            let stripe = (0..10)
                .filter_map(|i| {
                    let p = lp.facet_point
                        + lp.out_dir.into_inner() * (400.0 + 60.0 * i as f64)
                        + across * (i as f64 * 30.0 - 150.0);
                    let px = cam.point_to_pixel(&p)?;
                    Some(StripePoint { u: px.x, v: px.y, intensity: 100.0, width: 3.0, quality: 0 })
                })
                .collect();
            let mut f = Frame::new(seq, format!("{seq}.png"), alpha, facet);
            f.lasers = vec![laser];
            f.stripe = Some(stripe);
            w.write(&Record::Frame(Box::new(f))).unwrap();
        }
        drop(w);
        text
    };
    for (facet, laser, warned) in [(0, 0, false), (3, 0, true), (9, 0, false), (9, 1, true), (3, 1, false)] {
        let input = format!("f{facet}l{laser}.jsonl");
        std::fs::write(d.join(&input), stream(facet, laser)).unwrap();
        let out = run(d, &["--camera", "camera.json", "--scanner", "partial.json", &input, "-o", "out.jsonl"]);
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(out.status.success(), "{input}: {err}");
        let warning = format!("{input}: 3 frame(s) took points from light planes partial.json never calibrated");
        assert_eq!(err.contains(&warning) && err.contains("facets not seen on its rig: [3]"), warned, "{input}: {err}");
    }
}

#[test]
fn a_bad_facet_offset_is_blamed_on_scanner_json() {
    let fx = fixture();
    let d = fx.dir.path();
    let mut v: serde_json::Value = serde_json::from_slice(&std::fs::read(d.join("scanner.json")).unwrap()).unwrap();
    v["transmitter"]["lasers"][1]["facet_offset"] = 40.into();
    std::fs::write(d.join("bad_scanner.json"), v.to_string()).unwrap();
    let out = run(d, &["--camera", "camera.json", "--scanner", "bad_scanner.json", "ridges.jsonl"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(err.starts_with("omni-triangulate: error: bad_scanner.json:") && err.contains("facet_offset"), "{err}");
    assert!(!err.contains("ridges.jsonl"), "{err}");
}

#[test]
fn negative_numbers_reach_the_option_check() {
    let fx = fixture();
    let out = run(
        fx.dir.path(),
        &["--camera", "camera.json", "--scanner", "scanner.json", "--min-incidence-deg", "-5", "ridges.jsonl"],
    );
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(!err.contains("unexpected argument") && err.contains("incidence"), "{err}");
}

/// Names of the hidden temporary files in `dir`.
fn temp_files(dir: &Path) -> Vec<String> {
    std::fs::read_dir(dir)
        .unwrap()
        .filter_map(|e| e.ok())
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| n.contains("omniscan-tmp"))
        .collect()
}

#[test]
fn an_interrupted_run_leaves_no_temporary_file() {
    use std::io::Write as _;
    let fx = fixture();
    let d = fx.dir.path();
    let ridges = std::fs::read_to_string(fx.path("ridges.jsonl")).unwrap();
    let without_status: String =
        ridges.lines().filter(|l| !l.contains("\"status\"")).map(|l| format!("{l}\n")).collect();
    for signal in ["INT", "TERM"] {
        let mut child = Command::new(BIN)
            .current_dir(d)
            .args(["--camera", "camera.json", "--scanner", "scanner.json", "-", "-o", "out.jsonl"])
            .stdin(std::process::Stdio::piped())
            .stderr(std::process::Stdio::piped())
            .spawn()
            .unwrap();
        // The stream is still coming: the output's temporary file is open.
        let mut stdin = child.stdin.take().unwrap();
        stdin.write_all(without_status.as_bytes()).unwrap();
        stdin.flush().unwrap();
        let t0 = std::time::Instant::now();
        while temp_files(d).is_empty() {
            assert!(t0.elapsed().as_secs() < 20, "no temporary file appeared");
            std::thread::sleep(std::time::Duration::from_millis(20));
        }
        assert!(Command::new("kill").arg(format!("-{signal}")).arg(child.id().to_string()).status().unwrap().success());
        let status = child.wait().unwrap();
        drop(stdin);
        assert!(!status.success(), "{signal}: {status:?}");
        assert_eq!(temp_files(d), Vec::<String>::new(), "SIG{signal} left a temporary file");
        assert!(!fx.path("out.jsonl").exists());
    }
}

#[test]
fn stale_temporary_files_of_dead_runs_are_swept() {
    let fx = fixture();
    let d = fx.dir.path();
    let mut dead = Command::new("true").spawn().unwrap();
    let pid = dead.id();
    dead.wait().unwrap();
    let stale = fx.path(&format!(".out.jsonl.omniscan-tmp-{pid}"));
    std::fs::write(&stale, "left by a killed run").unwrap();
    let out = run(d, &["--camera", "camera.json", "--scanner", "scanner.json", "ridges.jsonl", "-o", "out.jsonl"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert!(!stale.exists() && fx.path("out.jsonl").exists());
}

#[test]
fn a_stream_cut_short_is_warned_about_and_passed_on_incomplete_or_refused_with_strict() {
    let fx = fixture();
    let d = fx.dir.path();
    let ridges = std::fs::read_to_string(fx.path("ridges.jsonl")).unwrap();
    let cut: String = ridges.lines().filter(|l| !l.contains("\"status\"")).map(|l| format!("{l}\n")).collect();
    std::fs::write(fx.path("cut.jsonl"), cut).unwrap();
    let out = run(d, &["--camera", "camera.json", "--scanner", "scanner.json", "cut.jsonl"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{err}");
    assert!(err.contains("warning: cut.jsonl") && err.contains("without its status record"), "{err}");
    let records: Vec<Record> = StreamReader::new(out.stdout.as_slice(), "out").map(|r| r.unwrap()).collect();
    let Some(Record::Status(status)) = records.last() else { panic!("no status record passed on") };
    assert!(!status.complete && status.frames == 3, "{status:?}");
    assert!(status.errors[0].contains("cut.jsonl"), "{status:?}");

    let out =
        run(d, &["--camera", "camera.json", "--scanner", "scanner.json", "cut.jsonl", "--strict", "-o", "o.jsonl"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(err.contains("cut.jsonl") && err.contains("--strict") && err.lines().count() == 1, "{err}");
    assert!(!fx.path("o.jsonl").exists());
    // A whole stream passes --strict and gives no warning.
    let out = run(d, &["--camera", "camera.json", "--scanner", "scanner.json", "ridges.jsonl", "--strict"]);
    assert!(out.status.success() && out.stderr.is_empty(), "{}", String::from_utf8_lossy(&out.stderr));
}

#[test]
fn rosbag_images_need_the_bag_and_every_frame_image() {
    let fx = fixture();
    let d = fx.dir.path();
    let base = ["--camera", "camera.json", "--scanner", "scanner.json", "ridges.jsonl", "--stamp-period-ms", "5"];
    let out = run(d, &[&base[..], &["--rosbag-images", "-o", "c.ply"]].concat());
    assert_eq!(out.status.code(), Some(2), "{}", String::from_utf8_lossy(&out.stderr));
    assert!(String::from_utf8_lossy(&out.stderr).contains("--rosbag-images needs --rosbag"));
    // The fixture's frames name images 0.png … that do not exist: the bag is refused whole.
    let out = run(d, &[&base[..], &["--rosbag", "bag", "--rosbag-images"]].concat());
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(err.contains("0.png") && err.lines().count() == 1, "{err}");
    assert!(!fx.path("bag").exists() && temp_files(d).is_empty());
    // Without the images the same bag is written.
    let out = run(d, &[&base[..], &["--rosbag", "bag"]].concat());
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert!(fx.path("bag/metadata.yaml").exists());
}

/// The stream, the cloud and the bag are put in place together: where one of them fails (a bag
/// directory that exists, a cloud in a missing directory, a frame image the bag cannot read)
/// none is left, not even a complete stream. Both to stdout is a usage error.
#[test]
fn a_run_that_fails_on_one_output_leaves_none() {
    let fx = fixture();
    let d = fx.dir.path();
    std::fs::create_dir(fx.path("taken")).unwrap();
    let base = ["--camera", "camera.json", "--scanner", "scanner.json", "ridges.jsonl", "-o", "out.jsonl"];
    let failing: [&[&str]; 3] = [
        &["--rosbag", "taken", "--stamp-period-ms", "5"],
        &["--cloud", "nodir/c.ply"],
        &["--cloud", "c.ply", "--rosbag", "bag", "--rosbag-images", "--stamp-period-ms", "5"],
    ];
    for extra in failing {
        let out = run(d, &[&base[..], extra].concat());
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{extra:?}: {err}");
        assert_eq!(err.lines().count(), 1, "{err}");
        assert!(!fx.path("out.jsonl").exists() && !fx.path("c.ply").exists() && !fx.path("bag").exists(), "{extra:?}");
        assert!(temp_files(d).is_empty(), "{extra:?}: {:?}", temp_files(d));
    }
    let out =
        run(d, &["--camera", "camera.json", "--scanner", "scanner.json", "ridges.jsonl", "-o", "-", "--cloud", "-"]);
    assert_eq!(out.status.code(), Some(2), "{}", String::from_utf8_lossy(&out.stderr));
    assert!(out.stdout.is_empty());
}

/// A fixed-plane scanner (kind fixed_planes): every frame's rays meet the one plane, whatever the
/// frame's mirror angle; a frame naming a laser without a plane is an error naming the field.
#[test]
fn triangulates_against_a_fixed_plane() {
    let fx = fixture();
    let tx = Transmitter::new(TransmitterParams::paper()).unwrap();
    let plane = tx.light_plane(15f64.to_radians(), 0, 0).unwrap().plane;
    write_doc(&fx.path("fixed.json"), &ScannerFile::new(omni_model::FixedPlanesParams::single(&plane))).unwrap();
    // Frame 1's pixels (taken at α = 15°), stamped with other angles and lasers [0].
    let text = std::fs::read_to_string(fx.path("ridges.jsonl")).unwrap();
    let mut out_text = Vec::new();
    {
        let mut w = StreamWriter::new(&mut out_text, "mem");
        for r in StreamReader::new(text.as_bytes(), "in") {
            match r.unwrap() {
                Record::Frame(mut f) if f.seq == 1 => {
                    f.alpha_deg = 77.0;
                    f.facet = 40;
                    f.lasers = vec![0];
                    w.write(&Record::Frame(f)).unwrap();
                }
                Record::Frame(_) => {}
                other => w.write(&other).unwrap(),
            }
        }
    }
    std::fs::write(fx.path("fixed.jsonl"), &out_text).unwrap();
    let out = run(fx.dir.path(), &["--camera", "camera.json", "--scanner", "fixed.json", "fixed.jsonl"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let points: Vec<[f64; 3]> = StreamReader::new(out.stdout.as_slice(), "out")
        .filter_map(|r| match r.unwrap() {
            Record::Frame(f) => Some(f.points.unwrap().iter().map(|p| p.xyz).collect::<Vec<_>>()),
            _ => None,
        })
        .flatten()
        .collect();
    assert_eq!(points.len(), fx.truth[1].len());
    for (p, t) in points.iter().zip(&fx.truth[1]) {
        assert!((Point3::from(*p) - t).norm() < 1e-6, "{p:?} vs {t}");
    }
    let bad = String::from_utf8(out_text).unwrap().replace("\"lasers\":[0]", "\"lasers\":[0,1]");
    std::fs::write(fx.path("bad.jsonl"), bad).unwrap();
    let out = run(fx.dir.path(), &["--camera", "camera.json", "--scanner", "fixed.json", "bad.jsonl"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(err.contains("field lasers: laser 1 has no plane"), "{err}");
}
