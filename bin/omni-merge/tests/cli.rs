//! The real omni-merge binary on small synthetic streams, PLY files and odometry.

use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};
use omni_cloud::filter::{radius_outlier_mask, statistical_outlier_mask};
use omni_cloud::rng::SplitMix64;
use omni_formats::odometry::{PoseSample, write_odometry};
use omni_formats::ply::{Encoding, PointCloud, ScalarField, read_ply, write_ply};
use omni_formats::stream::{Frame, Header, Point, Record, Status, StreamWriter, StripePoint};
use std::path::Path;
use std::process::{Command, Output};

#[path = "../../../tests/support/devices.rs"]
mod devices;
use devices::writes_into_devices;

const BIN: &str = env!("CARGO_BIN_EXE_omni-merge");

fn run(dir: &Path, args: &[&str]) -> Output {
    Command::new(BIN).current_dir(dir).args(args).output().unwrap()
}

fn ok(out: &Output) {
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
}

/// A point stream, one frame per element of `frames` (sensor-frame points, timestamp).
fn write_stream(path: &Path, frames: &[(Vec<[f64; 3]>, Option<u64>)]) {
    write_stream_seen_from(path, frames, None);
}

/// [`write_stream`] with the header's `viewpoint_mm`, as omni-triangulate writes it.
fn write_stream_seen_from(path: &Path, frames: &[(Vec<[f64; 3]>, Option<u64>)], viewpoint_mm: Option<[f64; 3]>) {
    let mut w = StreamWriter::new(std::fs::File::create(path).unwrap(), "test");
    w.write(&Record::Header(Header { viewpoint_mm, ..Header::new("test") })).unwrap();
    for (seq, (pts, ts)) in frames.iter().enumerate() {
        let mut f = Frame::new(seq as u64, "x.png", 10.0, 0);
        f.timestamp_us = *ts;
        f.stripe = Some(
            pts.iter()
                .enumerate()
                .map(|(i, _)| StripePoint { u: i as f64, v: 1.0, intensity: 50.0, width: 2.0, quality: 0 })
                .collect(),
        );
        f.points = Some(
            pts.iter()
                .enumerate()
                .map(|(i, p)| Point { xyz: *p, laser: 0, range: Vector3::from(*p).norm(), stripe_index: i as u32 })
                .collect(),
        );
        w.write(&Record::Frame(Box::new(f))).unwrap();
    }
    let status = Status::complete(frames.len() as u64);
    w.write(&Record::Status(status)).unwrap();
}

fn plane_with_outliers(rng: &mut SplitMix64, n: usize, outliers: usize) -> Vec<[f64; 3]> {
    let mut pts: Vec<[f64; 3]> =
        (0..n).map(|_| [rng.uniform() * 200.0, rng.uniform() * 200.0, 800.0 + rng.normal() * 0.3]).collect();
    for _ in 0..outliers {
        pts.push([rng.uniform() * 200.0, rng.uniform() * 200.0, 820.0 + rng.uniform() * 100.0]);
    }
    pts
}

#[test]
fn merges_streams_and_ply_and_matches_the_library_filters() {
    let dir = tempfile::tempdir().unwrap();
    let mut rng = SplitMix64::new(1);
    let a = plane_with_outliers(&mut rng, 1500, 30);
    let b = plane_with_outliers(&mut rng, 1500, 30);
    write_stream(&dir.path().join("a.jsonl"), &[(a[..800].to_vec(), None), (a[800..].to_vec(), None)]);
    let ply = PointCloud {
        positions: b.clone(),
        scalars: omni_cloud::cloud::POINT_SCALARS
            .iter()
            .map(|n| ScalarField::new(n.to_string(), vec![1.0; b.len()]))
            .collect(),
    };
    write_ply(&dir.path().join("b.ply"), &ply, Encoding::BinaryLittleEndian).unwrap();
    ok(&run(dir.path(), &["a.jsonl", "b.ply", "-o", "all.ply"]));
    let all = read_ply(&dir.path().join("all.ply")).unwrap();
    assert_eq!(all.len(), a.len() + b.len());
    assert_eq!(all.scalars.len(), 7);

    let both: Vec<[f64; 3]> = a.iter().chain(&b).copied().collect();
    ok(&run(dir.path(), &["a.jsonl", "b.ply", "-o", "sor.ply", "--statistical", "12,1.5"]));
    let sor = read_ply(&dir.path().join("sor.ply")).unwrap();
    let mask = statistical_outlier_mask(&both, 12, 1.5).unwrap();
    assert_eq!(sor.len(), mask.iter().filter(|k| **k).count());
    assert!(sor.positions.iter().all(|p| p[2] < 815.0), "a planted outlier survived");

    ok(&run(dir.path(), &["a.jsonl", "b.ply", "-o", "ror.ply", "--radius", "8,3", "--ascii"]));
    let ror = read_ply(&dir.path().join("ror.ply")).unwrap();
    let mask = radius_outlier_mask(&both, 3, 8.0).unwrap();
    assert_eq!(ror.len(), mask.iter().filter(|k| **k).count());

    ok(&run(dir.path(), &["a.jsonl", "b.ply", "-o", "vox.ply", "--voxel", "10", "--crop-box", "0,0,790,100,200,810"]));
    let vox = read_ply(&dir.path().join("vox.ply")).unwrap();
    // The plane z ≈ 800 over x ∈ [0, 100], y ∈ [0, 200] fills 10 × 20 voxels of the z = 790..800
    // and 800..810 layers; every centroid lies inside the box.
    assert!(vox.len() > 200 && vox.len() <= 400, "{}", vox.len());
    assert!(vox.positions.iter().all(|p| p[0] <= 100.0 && (790.0..=810.0).contains(&p[2])));
    // Deterministic: the same run gives the same bytes.
    ok(&run(dir.path(), &["a.jsonl", "b.ply", "-o", "vox2.ply", "--voxel", "10", "--crop-box", "0,0,790,100,200,810"]));
    assert_eq!(std::fs::read(dir.path().join("vox.ply")).unwrap(), std::fs::read(dir.path().join("vox2.ply")).unwrap());

    ok(&run(dir.path(), &["a.jsonl", "-o", "near.ply", "--crop-range", "0,850"]));
    let near = read_ply(&dir.path().join("near.ply")).unwrap();
    let expect = a.iter().filter(|p| Vector3::from(**p).norm() <= 850.0).count();
    assert_eq!(near.len(), expect);
}

#[test]
fn poses_put_a_moving_sensors_slices_into_one_world_frame() {
    let dir = tempfile::tempdir().unwrap();
    // The sensor drives along x at 0.5 mm/ms while yawing at 0.2 °/ms; odometry every 10 ms.
    let pose = |t_us: u64| {
        let t = t_us as f64 / 1000.0;
        Isometry3::from_parts(
            Translation3::new(0.5 * t, 0.0, 0.0),
            UnitQuaternion::from_axis_angle(&Vector3::z_axis(), (0.2 * t).to_radians()),
        )
    };
    write_poses(&dir.path().join("odo.jsonl"), 200_000, &pose);
    let world: Vec<Point3<f64>> =
        (0..200).map(|i| Point3::new(1000.0 + i as f64, 300.0 - 2.0 * i as f64, 50.0)).collect();
    let frames: Vec<(Vec<[f64; 3]>, Option<u64>)> = (0..10)
        .map(|k| {
            let t = 3_000 + k * 17_000;
            let inv = pose(t).inverse();
            (world[k as usize * 20..(k as usize + 1) * 20].iter().map(|w| (inv * w).coords.into()).collect(), Some(t))
        })
        .collect();
    write_stream(&dir.path().join("walk.jsonl"), &frames);
    ok(&run(dir.path(), &["--poses", "odo.jsonl", "walk.jsonl", "-o", "walk.ply"]));
    let cloud = read_ply(&dir.path().join("walk.ply")).unwrap();
    assert_eq!(cloud.len(), 200);
    let worst = cloud.positions.iter().zip(&world).map(|(p, w)| (Point3::from(*p) - w).norm()).fold(0.0, f64::max);
    assert!(worst < 1e-3, "worst {worst} mm");
    // Without poses the slices stay where the moving sensor saw them: far apart.
    ok(&run(dir.path(), &["walk.jsonl", "-o", "raw.ply"]));
    let raw = read_ply(&dir.path().join("raw.ply")).unwrap();
    let worst = raw.positions.iter().zip(&world).map(|(p, w)| (Point3::from(*p) - w).norm()).fold(0.0, f64::max);
    assert!(worst > 50.0);
}

#[test]
fn bad_inputs_fail_cleanly_without_output() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    write_stream(&d.join("s.jsonl"), &[(vec![[1.0, 2.0, 3.0]; 5], Some(5_000))]);
    let header = "{\"type\":\"header\",\"format\":\"omniscan.odometry\",\"version\":1}\n";
    let sample = |t: u64| format!("{{\"t_us\":{t},\"translation_mm\":[0,0,0],\"quaternion_wxyz\":[1,0,0,0]}}\n");
    std::fs::write(d.join("unsorted.jsonl"), format!("{header}{}{}", sample(9_000), sample(1_000))).unwrap();
    std::fs::write(d.join("gap.jsonl"), format!("{header}{}{}", sample(0), sample(900_000))).unwrap();
    std::fs::write(
        d.join("empty.ply"),
        "ply\nformat ascii 1.0\nelement vertex 0\nproperty float x\nproperty float y\nproperty float z\nend_header\n",
    )
    .unwrap();
    std::fs::write(d.join("nan.ply"), "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\nend_header\nnan 1 2\n").unwrap();
    std::fs::write(
        d.join("nopoints.jsonl"),
        "{\"type\":\"header\",\"format\":\"omniscan.stream\",\"version\":1}\n\
         {\"type\":\"frame\",\"seq\":4,\"path\":\"a.png\",\"alpha_deg\":3,\"facet\":0,\"stripe\":[]}\n",
    )
    .unwrap();
    let cases: [(&[&str], &str); 6] = [
        (&["--poses", "unsorted.jsonl", "s.jsonl"], "line 3"),
        (&["--poses", "gap.jsonl", "s.jsonl"], "gap"),
        (&["empty.ply"], "no vertices"),
        (&["nan.ply"], "vertex 0"),
        (&["nopoints.jsonl"], "frame 4"),
        (&["s.jsonl", "missing.jsonl"], "missing.jsonl"),
    ];
    for (args, expect) in cases {
        let mut all = args.to_vec();
        all.extend(["-o", "out.ply"]);
        let out = run(d, &all);
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{args:?}: {err}");
        assert!(err.contains(expect) && err.lines().count() == 1, "{args:?}: {err}");
        assert!(!d.join("out.ply").exists());
    }
    for bad in [&["s.jsonl", "-o", "o.ply", "--statistical", "0,2"][..], &["s.jsonl", "-o", "o.ply", "--radius", "x"]] {
        assert_eq!(run(d, bad).status.code(), Some(2));
    }
    assert_eq!(run(d, &["s.jsonl"]).status.code(), Some(2));
    // One stream named twice (here once through another path) would merge its points twice.
    let out = run(d, &["s.jsonl", "./s.jsonl", "-o", "o.ply"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(err.contains("./s.jsonl: given twice") && err.lines().count() == 1, "{err}");
    assert!(!d.join("o.ply").exists());
}

#[test]
fn dev_null_and_fifo_outputs_stay_what_they_are() {
    let dir = tempfile::tempdir().unwrap();
    let mut rng = SplitMix64::new(2);
    write_stream(&dir.path().join("a.jsonl"), &[(plane_with_outliers(&mut rng, 200, 0), None)]);
    let ply = writes_into_devices(dir.path(), |o| run(dir.path(), &["a.jsonl", "-o", o, "--ascii"]));
    assert!(ply.starts_with(b"ply\n") && String::from_utf8_lossy(&ply).contains("element vertex 200"));
}

#[test]
fn negative_numbers_reach_the_option_check() {
    let dir = tempfile::tempdir().unwrap();
    let mut rng = SplitMix64::new(2);
    write_stream(&dir.path().join("a.jsonl"), &[(plane_with_outliers(&mut rng, 50, 0), None)]);
    for (opt, val, expect) in [
        ("--voxel", "-1", "voxel"),
        ("--crop-box", "-1,-1,-1,-2,2,2", "crop"),
        ("--max-pose-gap-ms", "-3", "max-pose-gap-ms"),
        ("--statistical", "-4,2", "statistical"),
    ] {
        let out = run(dir.path(), &["a.jsonl", "-o", "c.ply", opt, val]);
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{opt} {val}: {err}");
        assert!(!err.contains("unexpected argument") && err.contains(expect), "{opt} {val}: {err}");
        assert!(!dir.path().join("c.ply").exists());
    }
}

/// A point beyond ±1e9 mm (here beyond a 32-bit cloud's range as well) is refused where it is
/// read, naming the stream's line, not written as inf.
#[test]
fn a_point_beyond_reach_is_refused_where_it_is_read() {
    let dir = tempfile::tempdir().unwrap();
    write_stream(&dir.path().join("a.jsonl"), &[(vec![[1.0, 2.0, 3.0], [1e40, 0.0, 500.0]], None)]);
    let out = run(dir.path(), &["a.jsonl", "-o", "c.ply", "--ascii"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(err.contains("a.jsonl: line 2") && err.contains("points[1]: 1e40 mm is beyond"), "{err}");
    assert!(!dir.path().join("c.ply").exists());
}

/// The cloud and the bag are put in place together: a bag that cannot be written leaves no
/// cloud either.
#[test]
fn a_bag_that_fails_leaves_no_cloud() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    write_stream(&d.join("a.jsonl"), &[(vec![[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]], Some(10))]);
    std::fs::create_dir(d.join("taken")).unwrap();
    for bag in ["taken", "nodir/bag"] {
        let out = run(d, &["a.jsonl", "-o", "c.ply", "--rosbag", bag]);
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{err}");
        assert!(err.contains(bag) && err.lines().count() == 1, "{err}");
        assert!(!d.join("c.ply").exists() && temporaries(d).is_empty(), "{bag}: {:?}", temporaries(d));
    }
    ok(&run(d, &["a.jsonl", "-o", "c.ply", "--rosbag", "bag"]));
    assert!(d.join("c.ply").is_file() && d.join("bag/metadata.yaml").is_file());
}

#[test]
fn a_repeated_frame_seq_is_refused_unless_allowed() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let mut rng = SplitMix64::new(4);
    write_stream(&d.join("a.jsonl"), &[(plane_with_outliers(&mut rng, 30, 0), None)]);
    let text = std::fs::read_to_string(d.join("a.jsonl")).unwrap();
    let frame = text.lines().find(|l| l.contains("\"frame\"")).unwrap();
    let doubled = text.replace(frame, &format!("{frame}\n{frame}"));
    std::fs::write(d.join("twice.jsonl"), doubled).unwrap();
    let out = run(d, &["twice.jsonl", "-o", "c.ply"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(
        err.contains("twice.jsonl: line 3 (frame 0)") && err.contains("line 2") && err.contains("--allow-duplicates"),
        "{err}"
    );
    assert!(!d.join("c.ply").exists());
    ok(&run(d, &["twice.jsonl", "-o", "c.ply", "--allow-duplicates"]));
    assert_eq!(read_ply(&d.join("c.ply")).unwrap().len(), 60);
    // The same seqs in two different streams are two scans, not a repeat; one file named twice is.
    std::fs::copy(d.join("a.jsonl"), d.join("b.jsonl")).unwrap();
    ok(&run(d, &["a.jsonl", "b.jsonl", "-o", "two.ply"]));
    assert_eq!(run(d, &["a.jsonl", "a.jsonl", "-o", "same.ply"]).status.code(), Some(2));
    ok(&run(d, &["a.jsonl", "a.jsonl", "-o", "same.ply", "--allow-duplicates"]));
}

#[test]
fn a_stream_cut_short_is_warned_about_or_refused_with_strict() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let mut rng = SplitMix64::new(5);
    write_stream(&d.join("a.jsonl"), &[(plane_with_outliers(&mut rng, 30, 0), None)]);
    let out = run(d, &["a.jsonl", "-o", "c.ply", "--strict"]);
    assert!(out.status.success() && out.stderr.is_empty(), "{}", String::from_utf8_lossy(&out.stderr));
    let text = std::fs::read_to_string(d.join("a.jsonl")).unwrap();
    let cut: String = text.lines().filter(|l| !l.contains("\"status\"")).map(|l| format!("{l}\n")).collect();
    std::fs::write(d.join("cut.jsonl"), cut).unwrap();
    let out = run(d, &["cut.jsonl", "-o", "cut.ply"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{err}");
    assert!(err.contains("warning: cut.jsonl") && err.contains("without its status record"), "{err}");
    let out = run(d, &["cut.jsonl", "-o", "strict.ply", "--strict"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(err.contains("cut.jsonl") && err.contains("--strict"), "{err}");
    assert!(!d.join("strict.ply").exists());
    // A stream whose status says it is incomplete (an interrupted scan): warned about, refused
    // with --strict, no cloud written.
    let incomplete = text.replace("\"complete\":true", "\"complete\":false");
    assert_ne!(incomplete, text);
    std::fs::write(d.join("incomplete.jsonl"), incomplete).unwrap();
    let out = run(d, &["incomplete.jsonl", "-o", "inc.ply"]);
    assert!(out.status.success() && String::from_utf8_lossy(&out.stderr).contains("marked incomplete"));
    let out = run(d, &["incomplete.jsonl", "-o", "inc_strict.ply", "--strict"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(err.contains("marked incomplete") && err.contains("--strict") && err.lines().count() == 1, "{err}");
    assert!(!d.join("inc_strict.ply").exists());
}

/// Odometry samples of `pose` every 10 ms over [0, `end_us`].
fn write_poses(path: &Path, end_us: u64, pose: &dyn Fn(u64) -> Isometry3<f64>) {
    let samples: Vec<PoseSample> = (0..=end_us / 10_000)
        .map(|i| {
            let p = pose(i * 10_000);
            let q = p.rotation;
            PoseSample {
                t_us: i * 10_000,
                translation_mm: p.translation.vector.into(),
                quaternion_wxyz: [q.w, q.i, q.j, q.k],
            }
        })
        .collect();
    write_odometry(path, &samples).unwrap();
}

#[test]
fn normals_under_poses_face_the_sensor_of_their_own_frame() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // A wall through n·p = 1000 mm (n tilted from +x). Frames 0–3 (t 0–30 ms) see its y < 0 half
    // from the origin; the sensor then drives round it and frames 4–7 (t 200–230 ms) see the
    // y > 0 half from behind, at 2000·n + (0, 300, 0) turned 180° about z. The world origin lies
    // on the front side, so normals turned towards it would face away from frames 4–7's sensor.
    let n = Vector3::new(1.0, 0.2, 0.1).normalize();
    let a = Isometry3::identity();
    let b = Isometry3::from_parts(
        Translation3::from(2000.0 * n + Vector3::new(0.0, 300.0, 0.0)),
        UnitQuaternion::from_axis_angle(&Vector3::z_axis(), std::f64::consts::PI),
    );
    let pose = |t_us: u64| {
        let s = ((t_us as f64 - 50_000.0) / 100_000.0).clamp(0.0, 1.0);
        a.lerp_slerp(&b, s)
    };
    write_poses(&d.join("odo.jsonl"), 300_000, &pose);
    let (e1, e2) = (n.cross(&Vector3::z()).normalize(), n.cross(&n.cross(&Vector3::z())).normalize());
    let mut rng = SplitMix64::new(21);
    let mut frames = Vec::new();
    for k in 0..8u64 {
        let t = if k < 4 { k * 10_000 } else { 200_000 + (k - 4) * 10_000 };
        // e1 ≈ −y: frames 0–3 take the patch at e1 > 20 mm (y < 0), frames 4–7 at e1 < −20 mm.
        let side = if k < 4 { 1.0 } else { -1.0 };
        let inv = pose(t).inverse();
        let pts = (0..250)
            .map(|_| {
                let w = 1000.0 * n
                    + e1 * side * (20.0 + rng.uniform() * 200.0)
                    + e2 * (rng.uniform() * 300.0 - 150.0)
                    + n * rng.normal() * 0.1;
                (inv * Point3::from(w)).coords.into()
            })
            .collect();
        frames.push((pts, Some(t)));
    }
    write_stream(&d.join("walk.jsonl"), &frames);
    let viewpoint = |seq: f32| pose(if seq < 3.5 { 0 } else { 200_000 }).translation.vector;
    assert!(n.dot(&viewpoint(5.0)) > 1000.0 && n.dot(&viewpoint(0.0)) < 1000.0, "the sensor sees both sides");

    for (name, extra) in [("points.ply", &[][..]), ("voxels.ply", &["--voxel", "15"][..])] {
        let mut args = vec!["--poses", "odo.jsonl", "walk.jsonl", "-o", name, "--normals"];
        args.extend(extra);
        ok(&run(d, &args));
        let cloud = read_ply(&d.join(name)).unwrap();
        assert!(cloud.len() > if extra.is_empty() { 1999 } else { 300 }, "{name}: {}", cloud.len());
        let names: Vec<&str> = cloud.scalars.iter().map(|s| s.name.as_str()).collect();
        assert!(names.ends_with(&["nx", "ny", "nz"]) && !names.iter().any(|s| s.contains("viewpoint")), "{names:?}");
        let [nx, ny, nz] = ["nx", "ny", "nz"].map(|f| cloud.scalar(f).unwrap());
        let seq = cloud.scalar("scalar_frame").unwrap();
        let mut back = 0;
        for (i, p) in cloud.positions.iter().enumerate() {
            let normal = Vector3::new(nx[i], ny[i], nz[i]).cast::<f64>();
            // A voxel holds one side's points only (the halves are 40 mm apart, a voxel's
            // diagonal 26 mm), so its mean frame number tells the side.
            let to_view = viewpoint(seq[i]) - Vector3::from(*p);
            assert!(normal.dot(&to_view) > 0.0, "{name}: point {i} (frame {}) faces away from its sensor", seq[i]);
            let truth = if seq[i] < 3.5 { -n } else { n };
            // 0.1 mm noise over a 16-neighbour patch ~ 10 mm across (voxels: ~ 60 mm): < 3°.
            let angle = normal.angle(&truth).to_degrees();
            assert!(angle < 3.0, "{name}: point {i}: {angle}° from the wall's normal");
            back += (seq[i] > 3.5) as usize;
        }
        assert!(back > cloud.len() / 3, "{name}: {back} of {} points seen from behind", cloud.len());
    }
}

/// A shelf at the sensor's own height, between the camera (the origin) and the mirror focus F
/// (0, 0, 80 mm) that every ray starts from: its normals face F, up, not the camera below it,
/// with the sensor still and moved by a pose alike.
#[test]
fn normals_face_the_streams_viewpoint_not_the_sensor_origin() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let mut rng = SplitMix64::new(5);
    let shelf: Vec<[f64; 3]> = (0..600)
        .map(|_| [300.0 + rng.uniform() * 200.0, rng.uniform() * 200.0 - 100.0, 40.0 + rng.normal() * 0.05])
        .collect();
    // Spread over 12 frames (one frame's points would be one stripe, which fixes no plane).
    let frames: Vec<(Vec<[f64; 3]>, Option<u64>)> =
        (0..12).map(|k| (shelf.iter().skip(k).step_by(12).copied().collect(), Some(k as u64 * 1000))).collect();
    write_stream_seen_from(&d.join("shelf.jsonl"), &frames, Some([0.0, 0.0, 80.0]));
    // The sensor lifted 500 mm: the shelf at z = 540 is seen from F at z = 580.
    write_poses(&d.join("lift.jsonl"), 20_000, &|_| Isometry3::translation(0.0, 0.0, 500.0));
    for (name, poses) in [("still.ply", &[][..]), ("lifted.ply", &["--poses", "lift.jsonl"][..])] {
        let mut args = vec!["shelf.jsonl", "-o", name, "--normals"];
        args.extend(poses);
        ok(&run(d, &args));
        let cloud = read_ply(&d.join(name)).unwrap();
        let nz = cloud.scalar("nz").unwrap();
        assert_eq!(nz.len(), 600, "{name}");
        assert!(
            nz.iter().all(|&z| z > 0.99),
            "{name}: a normal faces down: {:?}",
            nz.iter().cloned().fold(1.0, f32::min)
        );
    }
    // A PLY carries no viewpoint: its normals face the origin, and the tool says so.
    let out = run(d, &["still.ply", "-o", "again.ply", "--normals"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success() && err.contains("still.ply: a PLY cloud carries no viewpoint"), "{err}");
}

/// The omniscan temporary entries (files or directories) in `dir`.
fn temporaries(dir: &Path) -> Vec<std::path::PathBuf> {
    std::fs::read_dir(dir)
        .unwrap()
        .filter_map(|e| e.ok())
        .filter(|e| e.file_name().to_string_lossy().contains(".omniscan-tmp-"))
        .map(|e| e.path())
        .collect()
}

/// Starts `omni-merge big.ply --rosbag bag` and stops it (SIGSTOP) while the bag's temporary
/// directory exists; `None` if the write finished before it could be caught.
fn stopped_mid_bag_write(d: &Path) -> Option<std::process::Child> {
    let mut child = Command::new(BIN)
        .current_dir(d)
        .args(["big.ply", "--rosbag", "bag"])
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let pid = child.id() as libc::pid_t;
    loop {
        if temporaries(d).iter().any(|p| p.is_dir()) {
            // SAFETY: kill sends a signal to our own child.
            assert_eq!(unsafe { libc::kill(pid, libc::SIGSTOP) }, 0);
            // Stopped mid-write only if the temporary is still there and the bag is not.
            if temporaries(d).iter().any(|p| p.is_dir()) && !d.join("bag").exists() {
                return Some(child);
            }
            unsafe { libc::kill(pid, libc::SIGCONT) };
        }
        if child.try_wait().unwrap().is_some() {
            let _ = std::fs::remove_dir_all(d.join("bag"));
            return None;
        }
    }
}

#[test]
fn an_interrupted_bag_write_leaves_no_directory_and_a_killed_ones_is_swept() {
    use std::os::unix::process::ExitStatusExt;
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // Big enough that writing its bag (~ 40 bytes a point) takes tens of milliseconds; each
    // missed attempt doubles it.
    let mut n = 100_000;
    let mut caught = |signal: i32| loop {
        let mut rng = SplitMix64::new(n as u64);
        let positions: Vec<[f64; 3]> = (0..n).map(|_| [rng.uniform() * 1e3, rng.uniform() * 1e3, 500.0]).collect();
        let scalars = omni_cloud::cloud::POINT_SCALARS
            .iter()
            .map(|name| ScalarField::new(name.to_string(), vec![1.0; n]))
            .collect();
        write_ply(&d.join("big.ply"), &PointCloud { positions, scalars }, Encoding::BinaryLittleEndian).unwrap();
        if let Some(mut child) = stopped_mid_bag_write(d) {
            let pid = child.id() as libc::pid_t;
            // SAFETY: signals to our own stopped child.
            unsafe {
                assert_eq!(libc::kill(pid, signal), 0);
                libc::kill(pid, libc::SIGCONT);
            }
            return child.wait().unwrap();
        }
        n *= 2;
        assert!(n <= 800_000, "the bag write was never caught in progress");
    };
    for signal in [libc::SIGTERM, libc::SIGINT] {
        let status = caught(signal);
        assert_eq!(status.signal(), Some(signal), "{status:?}");
        assert!(!d.join("bag").exists(), "signal {signal} left the bag directory");
        assert_eq!(temporaries(d), Vec::<std::path::PathBuf>::new(), "signal {signal} left a temporary");
    }
    // SIGKILL cannot be caught: the temporary directory stays, and the next run in the
    // directory sweeps it (its process is gone) before writing its own bag.
    let status = caught(libc::SIGKILL);
    assert_eq!(status.signal(), Some(libc::SIGKILL));
    let left = temporaries(d);
    assert!(left.len() == 1 && left[0].is_dir() && !d.join("bag").exists(), "{left:?}");
    ok(&run(d, &["big.ply", "--rosbag", "bag2"]));
    assert_eq!(temporaries(d), Vec::<std::path::PathBuf>::new(), "the stale temporary directory was not swept");
    assert!(d.join("bag2/bag2_0.mcap").is_file() && d.join("bag2/metadata.yaml").is_file());
}
