//! Scenes, shadows, occlusions, boards and the rig: behaviour checked against geometry worked
//! out independently of the renderer.

use omni_formats::BoardFile;
use omni_formats::scene::{SceneFile, SceneObject, Shape};
use omni_geom::{Isometry3, Plane, Point3, Vector2, Vector3, intersect_ray_plane};
use omni_simulator::{
    BenchObject, RenderOptions, Rig, Scene, Sensor, check_boards_visible, paper_bench, random_board_poses,
    render_ambient_frame, render_board_image, render_laser_frame, stripe_truth,
};
use std::path::PathBuf;

fn testdata(rel: &str) -> PathBuf {
    PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../../testdata")).join(rel)
}

fn scene(objects: Vec<Shape>) -> Scene {
    Scene::from_file(SceneFile::new(objects.into_iter().map(SceneObject::new).collect())).unwrap()
}

fn bench_plane() -> Shape {
    Shape::Rectangle {
        centre_mm: [500.0, 0.0, 0.0],
        normal: [-1.0, 0.0, 0.0],
        up: [0.0, 0.0, 1.0],
        width_mm: 400.0,
        height_mm: 300.0,
    }
}

#[test]
fn shipped_scenes_are_the_paper_bench() {
    for (file, object) in [
        ("plane.json", BenchObject::Plane),
        ("cylinder.json", BenchObject::Cylinder),
        ("sphere.json", BenchObject::Sphere),
        ("cone_pyramid.json", BenchObject::ConePyramid),
    ] {
        let s = Scene::load(&testdata("scenes").join(file)).unwrap();
        assert_eq!(s.file(), &paper_bench(object), "{file}");
    }
    let room = Scene::load(&testdata("scenes/room.json")).unwrap();
    assert_eq!(room.len(), 4);
    check_boards_visible(&Sensor::paper_scaled(256), &room).unwrap();
}

#[test]
fn bad_scenes_get_clear_errors() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("bad.json");
    let text = std::fs::read_to_string(testdata("scenes/sphere.json")).unwrap();
    std::fs::write(&path, text.replace("\"sphere\"", "\"torus\"")).unwrap();
    let e = Scene::load(&path).unwrap_err().to_string();
    assert!(e.contains("bad.json") && e.contains("unknown variant `torus`"), "{e}");
    std::fs::write(&path, text.replace("50.0", "-50.0")).unwrap();
    let e = Scene::load(&path).unwrap_err().to_string();
    assert!(e.contains("bad.json") && e.contains("objects[0]") && e.contains("radius_mm must be a positive"), "{e}");

    // A board straight above the mirror, facing down: beyond the rim's +37° elevation.
    let above = scene(vec![Shape::Checkerboard {
        centre_mm: [0.0, 0.0, 3000.0],
        normal: [0.0, 0.0, -1.0],
        up: [1.0, 0.0, 0.0],
        square_mm: 30.0,
        inner_cols: 9,
        inner_rows: 6,
        margin_mm: 30.0,
        dark_albedo: 0.05,
    }]);
    let e = check_boards_visible(&Sensor::paper_scaled(256), &above).unwrap_err();
    assert!(e.contains("objects[0]") && e.contains("never enters"), "{e}");
}

/// The light plane of laser 0 at α = 20° meets x = 300 at z ≈ −57 mm and x = 500 at z ≈ −22 mm.
fn stripe_z(sensor: &Sensor, alpha: f64, x: f64) -> f64 {
    let (slope, intercept) = sensor.transmitter.light_plane(alpha, 0, 0).unwrap().slope_intercept();
    slope * x + intercept
}

#[test]
fn laser_shadows_are_dark_and_absent_from_truth() {
    let sensor = Sensor::paper_scaled(512);
    let alpha = 20f64.to_radians();
    let z_box = stripe_z(&sensor, alpha, 300.0);
    let blocker = Shape::Box { centre_mm: [300.0, 0.0, z_box], size_mm: [20.0, 40.0, 40.0], rotation_deg: [0.0; 3] };
    let s = scene(vec![bench_plane(), blocker]);
    let truth = stripe_truth(&sensor, &s, alpha, 0, &[0]);
    let on_plane: Vec<_> = truth.iter().filter(|t| (t.xyz[0] - 500.0).abs() < 1e-6).collect();
    let on_box = truth.iter().filter(|t| (t.xyz[0] - 290.0).abs() < 1e-6).count();
    assert!(on_box > 10, "the box's front face is lit: {on_box} points");
    // Fan rays come from the virtual source (the laser apex mirrored in the facet, y = 0): those
    // through the box's front face (x = 290, |y| ≤ 20) reach the plane at |y| ≤ edge.
    let vs = sensor.transmitter.light_plane(alpha, 0, 0).unwrap().virtual_source;
    let edge = 20.0 * (500.0 - vs.x) / (290.0 - vs.x);
    let inside: Vec<_> = on_plane.iter().filter(|t| t.xyz[1].abs() <= edge - 0.01).collect();
    assert!(inside.is_empty(), "truth points inside the shadow (|y| < {edge}): {:?}", &inside[..inside.len().min(3)]);
    assert!(on_plane.iter().any(|t| t.xyz[1].abs() < edge + 0.5), "truth ends at the shadow edge {edge}");

    let opts = RenderOptions::ideal_noiseless();
    let lit = render_laser_frame(&sensor, &s, alpha, 0, &[0], &opts).image;
    let dark = render_ambient_frame(&sensor, &s, &opts);
    let z_plane = stripe_z(&sensor, alpha, 500.0);
    let excess = |y: f64| {
        let px = sensor.camera.point_to_pixel(&Point3::new(500.0, y, z_plane)).unwrap();
        let (x, y) = (px.x.round() as u32, px.y.round() as u32);
        (-1..=1)
            .flat_map(|d: i32| [(x as i32 + d, y as i32), (x as i32, y as i32 + d)])
            .map(|(x, y)| lit.get(x as u32, y as u32) as i32 - dark.get(x as u32, y as u32) as i32)
            .max()
            .unwrap()
    };
    assert!(excess(0.0) <= 1, "shadowed stripe is lit: {}", excess(0.0));
    assert!(excess(80.0) > 60, "unshadowed stripe is dark: {}", excess(80.0));
}

#[test]
fn camera_occlusions_hide_the_stripe() {
    let sensor = Sensor::paper_scaled(512);
    let alpha = 20f64.to_radians();
    // A screen at x = 300 above the light plane (z from −35 to 45 mm): the laser passes under
    // it, but it hides the plane's stripe (seen from F = (0, 0, 80) through z ≈ 19 mm there).
    let screen = Shape::Rectangle {
        centre_mm: [300.0, 0.0, 5.0],
        normal: [-1.0, 0.0, 0.0],
        up: [0.0, 0.0, 1.0],
        width_mm: 120.0,
        height_mm: 80.0,
    };
    let open = stripe_truth(&sensor, &scene(vec![bench_plane()]), alpha, 0, &[0]);
    let hidden = stripe_truth(&sensor, &scene(vec![bench_plane(), screen]), alpha, 0, &[0]);
    // Lines of sight from F to the stripe at x = 500 cross x = 300 at y·0.6: the screen's
    // |y| ≤ 60 hides |y| ≤ 100 mm.
    assert!(open.iter().any(|t| t.xyz[1].abs() < 90.0));
    assert!(hidden.iter().all(|t| t.xyz[1].abs() > 99.0), "a hidden point is in the truth");
    assert!(hidden.len() > open.len() / 3);
}

#[test]
fn default_stripe_level_is_a_real_unsaturated_stripe() {
    let sensor = Sensor::paper();
    let s = Scene::from_file(paper_bench(BenchObject::Plane)).unwrap();
    let opts = RenderOptions::ideal_noiseless();
    let frame = render_laser_frame(&sensor, &s, 20f64.to_radians(), 0, &[0], &opts);
    let peaks: Vec<u16> = frame
        .truth
        .iter()
        .filter(|t| t.xyz[1].abs() < 50.0)
        .map(|t| frame.image.get(t.pixel[0].round() as u32, t.pixel[1].round() as u32))
        .collect();
    let max = *peaks.iter().max().unwrap();
    let min = *peaks.iter().min().unwrap();
    eprintln!("stripe peak on the bench plane near y = 0: {min}..{max} of 255");
    assert!(min >= 150 && max <= 220, "{min}..{max}");
}

#[test]
fn motion_blur_widens_the_stripe_about_the_same_centre() {
    let sensor = Sensor::paper_scaled(512);
    let s = Scene::from_file(paper_bench(BenchObject::Plane)).unwrap();
    let alpha = 20f64.to_radians();
    let still = RenderOptions { ambient_e: 0.0, ..RenderOptions::ideal_noiseless() };
    let moving = RenderOptions { motion_blur_deg: 0.5, ..still.clone() };
    let a = render_laser_frame(&sensor, &s, alpha, 0, &[0], &still);
    let b = render_laser_frame(&sensor, &s, alpha, 0, &[0], &moving);
    // The stripe on the plane near y = 0 is horizontal in the world: a radial profile in the image.
    let t = a.truth.iter().min_by(|p, q| p.xyz[1].abs().total_cmp(&q.xyz[1].abs())).unwrap();
    let centre = sensor.camera.mirror_circle().centre;
    let dir = (Vector2::from(t.pixel) - centre).normalize();
    let profile = |f: &omni_simulator::Frame16| {
        let (mut s0, mut s1, mut s2) = (0.0, 0.0, 0.0);
        for i in -80..=80 {
            let o = i as f64 * 0.1;
            let q = Vector2::from(t.pixel) + dir * o;
            let v = f.bilinear(q.x, q.y).unwrap();
            s0 += v;
            s1 += v * o;
            s2 += v * o * o;
        }
        let mean = s1 / s0;
        (mean, (s2 / s0 - mean * mean).sqrt())
    };
    let ((ca, wa), (cb, wb)) = (profile(&a.image), profile(&b.image));
    // Expected: the still profile convolved with a uniform smear between the stripe's positions
    // at the start and end of the exposure (variance L²/12).
    let at = |da: f64| {
        let tr = stripe_truth(&sensor, &s, alpha + da.to_radians(), 0, &[0]);
        let p = tr.iter().min_by(|p, q| p.xyz[1].abs().total_cmp(&q.xyz[1].abs())).unwrap();
        Vector2::from(p.pixel)
    };
    let smear = (at(0.25) - at(-0.25)).norm();
    let expected = (wa * wa + smear * smear / 12.0).sqrt();
    eprintln!(
        "still: centre {ca:.3} px, width {wa:.3} px; 0.5° blur: smear {smear:.2} px, centre {cb:.3} px, width {wb:.3} px (expected {expected:.3})"
    );
    assert!(ca.abs() < 0.05, "{ca}");
    assert!((wb - expected).abs() < 0.05 * expected, "blurred width {wb}, expected {expected}");
    assert!(cb.abs() < 0.1, "the blurred stripe stays centred on the mid-exposure plane: {cb}");
}

fn board() -> BoardFile {
    omni_formats::read_doc(&testdata("boards/board_9x6.json")).unwrap()
}

/// Pixel of a board point (board frame, mm).
fn board_pixel(sensor: &Sensor, pose: &Isometry3<f64>, x: f64, y: f64) -> Option<Vector2<f64>> {
    sensor.camera.point_to_pixel(&(pose * Point3::new(x, y, 0.0)))
}

#[test]
fn board_images_follow_the_board_convention() {
    let sensor = Sensor::paper_scaled(512);
    let b = board();
    let rig = Rig::standard(&b);
    let opts = RenderOptions::calibration().noiseless_copy();
    for pose in &rig.poses {
        let (image, corners) = render_board_image(&sensor, pose, &b, &opts);
        let plane = Plane::from_point_normal(&(pose * Point3::origin()), &pose.transform_vector(&Vector3::z()));
        let mut seen = 0;
        for (k, c) in corners.iter().enumerate() {
            let Some(px) = c else { continue };
            seen += 1;
            let ray = sensor.camera.pixel_to_ray(&Vector2::from(*px)).unwrap();
            let hit = intersect_ray_plane(&ray, &plane, 1e-6).unwrap();
            let (col, row) = ((k % 9) as f64, (k / 9) as f64);
            let expected = pose * Point3::new(col * 30.0, row * 30.0, 0.0);
            assert!((hit.point - expected).norm() < 1e-6, "corner {k}");
        }
        assert_eq!(seen, 54, "the rig's boards are fully in view");
        // Square (0, 0) (top-left, x < 0, y < 0 of the first corner) is black, its neighbours white.
        let value = |x: f64, y: f64| {
            let p = board_pixel(&sensor, pose, x, y).unwrap();
            image.get(p.x.round() as u32, p.y.round() as u32)
        };
        let (black, white) = (value(-15.0, -15.0), value(15.0, -15.0));
        assert!(black < 20 && white > 120, "black {black}, white {white}");
        assert!(value(15.0, 15.0) < 20 && value(-15.0, 15.0) > 120);
    }
}

trait NoiselessCopy {
    fn noiseless_copy(self) -> Self;
}

impl NoiselessCopy for RenderOptions {
    fn noiseless_copy(self) -> Self {
        RenderOptions { noise: false, ..self }
    }
}

#[test]
fn random_boards_are_in_view_some_partly() {
    let sensor = Sensor::paper_scaled(256);
    let b = board();
    let poses = random_board_poses(&sensor, &b, 20, 5).unwrap();
    assert_eq!(poses.len(), 20);
    let s =
        |pose: &Isometry3<f64>| Scene::from_file(SceneFile::new(vec![omni_simulator::board_object(&b, pose)])).unwrap();
    let visible: Vec<usize> =
        poses.iter().map(|p| omni_simulator::corner_pixels(&sensor, &s(p), p, &b).iter().flatten().count()).collect();
    assert!(visible.iter().all(|v| *v > 0), "{visible:?}");
    assert!(visible.iter().any(|v| *v < 54), "no board partly out of view: {visible:?}");
    assert!(visible.iter().filter(|v| **v == 54).count() >= 5, "too few whole boards: {visible:?}");
    let centres: Vec<f64> = poses.iter().map(|p| p.translation.vector.xy().norm()).collect();
    assert!(centres.iter().all(|d| *d > 150.0 && *d < 1100.0), "{centres:?}");
    assert_eq!(random_board_poses(&sensor, &b, 20, 5).unwrap(), poses, "same seed, same poses");
}

#[test]
fn rig_boards_are_perpendicular_and_both_crossed_by_laser_0() {
    let sensor = Sensor::paper_scaled(256);
    let rig = Rig::standard(&board());
    let n0 = rig.poses[0].transform_vector(&Vector3::z());
    let n1 = rig.poses[1].transform_vector(&Vector3::z());
    assert!(n0.dot(&n1).abs() < 1e-12);
    let s = Scene::from_file(rig.scene()).unwrap();
    for alpha_deg in [16.0, 20.0, 24.0] {
        let truth = stripe_truth(&sensor, &s, f64::to_radians(alpha_deg), 0, &[0]);
        let left = truth.iter().filter(|t| t.xyz[1] > 5.0).count();
        let right = truth.iter().filter(|t| t.xyz[1] < -5.0).count();
        assert!(left > 50 && right > 50, "α {alpha_deg}: {left} / {right} points on the boards");
    }
}
