//! The camera's signal chain against its documented model: mean level, photon + read noise,
//! gamma, saturation.

use omni_formats::scene::{SceneFile, SceneObject, Shape};
use omni_simulator::{
    BenchObject, RenderOptions, Scene, Sensor, paper_bench, render_ambient_frame, render_laser_frame,
};

/// A room seen in every direction, albedo 0.5: every pixel in the mirror annulus collects
/// 0.5 · ambient_e electrons.
fn grey_room() -> Scene {
    let room = Shape::Room { centre_mm: [0.0, 0.0, 0.0], size_mm: [3000.0, 3000.0, 3000.0] };
    Scene::from_file(SceneFile::new(vec![SceneObject { name: None, albedo: 0.5, shape: room }])).unwrap()
}

/// Pixels well inside the mirror annulus (away from the rim and blind centre, blurred there).
fn annulus_pixels(sensor: &Sensor) -> Vec<usize> {
    let c = sensor.camera.mirror_circle();
    let (w, h) = sensor.camera.image_size();
    (0..(w * h) as usize)
        .filter(|&i| {
            let (x, y) = ((i % w as usize) as f64, (i / w as usize) as f64);
            let r = (x - c.centre.x).hypot(y - c.centre.y);
            r > c.inner_radius + 4.0 && r < c.outer_radius - 4.0
        })
        .collect()
}

#[test]
fn level_and_noise_follow_photon_and_read_noise() {
    let sensor = Sensor::paper_scaled(192);
    let scene = grey_room();
    let opts = RenderOptions { bit_depth: 16, ..Default::default() };
    let gain = 65535.0 / opts.full_well_e; // DN per electron
    let signal_e = 0.5 * opts.ambient_e;
    let a = render_ambient_frame(&sensor, &scene, &RenderOptions { seed: 1, ..opts.clone() });
    let b = render_ambient_frame(&sensor, &scene, &RenderOptions { seed: 2, ..opts.clone() });
    let px = annulus_pixels(&sensor);
    let n = px.len() as f64;
    let mean = px.iter().map(|&i| a.data[i] as f64).sum::<f64>() / n;
    let var_diff = px.iter().map(|&i| (a.data[i] as f64 - b.data[i] as f64).powi(2)).sum::<f64>() / n;
    let sigma = (var_diff / 2.0).sqrt();
    let expected = (signal_e + opts.read_noise_e.powi(2)).sqrt() * gain;
    eprintln!("{n} px: mean {mean:.1} DN (expected {:.1}), σ {sigma:.1} DN (expected {expected:.1})", signal_e * gain);
    assert!((mean / (signal_e * gain) - 1.0).abs() < 0.005, "mean {mean}");
    assert!((sigma / expected - 1.0).abs() < 0.05, "σ {sigma}, expected {expected}");
}

#[test]
fn gamma_and_quantisation() {
    let sensor = Sensor::paper_scaled(96);
    let scene = grey_room();
    let opts = RenderOptions { gamma: 2.2, ..RenderOptions::noiseless() };
    let f = render_ambient_frame(&sensor, &scene, &opts);
    let expected = (255.0 * (0.5 * opts.ambient_e / opts.full_well_e).powf(1.0 / 2.2)).round() as u16;
    assert!(annulus_pixels(&sensor).iter().all(|&i| f.data[i] == expected), "expected {expected}");
}

#[test]
fn strong_laser_saturates_at_full_scale() {
    let sensor = Sensor::paper_scaled(256);
    let scene = Scene::from_file(paper_bench(BenchObject::Plane)).unwrap();
    let normal = render_laser_frame(&sensor, &scene, 0.35, 0, &[0], &RenderOptions::noiseless());
    let strong =
        RenderOptions { laser_strength: 10.0 * RenderOptions::default().laser_strength, ..RenderOptions::noiseless() };
    let hot = render_laser_frame(&sensor, &scene, 0.35, 0, &[0], &strong);
    let saturated = |f: &omni_simulator::Frame16| f.data.iter().filter(|v| **v == 255).count();
    assert_eq!(saturated(&normal.image), 0, "the default stripe is unsaturated");
    assert!(saturated(&hot.image) > 50, "a 10× laser saturates: {}", saturated(&hot.image));
    assert!(hot.image.data.iter().all(|v| *v <= 255));
}
