//! A lens focused at a distance: each part of the catadioptric frame blurred by its own defocus.

use crate::*;

/// The paper's sensor in a room (laser 0 at 10° lights its walls 160–225 px from the image
/// centre, where the lens focused at 91 mm blurs by σ 0.3–1.0 px).
fn room() -> (Sensor, Scene) {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../../testdata/scenes/room.json");
    (Sensor::paper(), Scene::load(std::path::Path::new(path)).unwrap())
}

/// The paper's lens, no noise, no ambient light, 16 bits, the laser imaged incoherently unless
/// `speckle`, focused at `focus_mm` or in focus everywhere.
fn lens(focus_mm: Option<f64>, speckle: bool) -> RenderOptions {
    let sharp = Optics { defocus_px: 0.0, speckle_patterns: 16, ..Optics::paper() };
    let optics = focus_mm.map_or(sharp, |f| sharp.focused_at(f));
    RenderOptions {
        noise: false,
        ambient_e: 0.0,
        bit_depth: 16,
        full_well_e: 1e6,
        imaging: Imaging::Lens { optics, speckle },
        ..RenderOptions::default()
    }
}

/// The stripe's variance across (px²) at each usable laser-0 truth point: of the light of the
/// pixels within ±`reach` px across the stripe (along the sheet gradient) and ±5 px along it,
/// so that pixel centres fall at many phases across it; with the point's radius from the image
/// centre and its σ of defocus (px) at `optics`. `None` for points near other light or an edge;
/// every third truth point, in order.
fn variances_across(
    sensor: &Sensor,
    scene: &Scene,
    alpha: f64,
    frame: &LaserFrame,
    optics: &Optics,
    reach: f64,
) -> Vec<Option<(f64, f64, f64)>> {
    let camera = sensor.camera.as_ref();
    let image = &frame.image;
    frame
        .truth
        .iter()
        .filter(|t| t.laser == 0)
        .step_by(3)
        .map(|t| {
            let g = sheet_gradient_at(sensor, scene, alpha, 0, t)?;
            let n = (g[0] * g[0] + g[1] * g[1]).sqrt();
            let (nx, ny) = (g[0] / n, g[1] / n);
            let box_px = (reach + 6.0).ceil() as i64;
            let (cx, cy) = (t.pixel[0].round() as i64, t.pixel[1].round() as i64);
            let (mut sum, mut first, mut second, mut edge) = (0.0, 0.0, 0.0, 0.0f64);
            let mut peak = 0.0f64;
            for y in cy - box_px..=cy + box_px {
                for x in cx - box_px..=cx + box_px {
                    if x < 0 || y < 0 || x >= image.width as i64 || y >= image.height as i64 {
                        return None;
                    }
                    let (dx, dy) = (x as f64 - t.pixel[0], y as f64 - t.pixel[1]);
                    let (across, along) = (dx * nx + dy * ny, -dx * ny + dy * nx);
                    if along.abs() > 5.0 || across.abs() > reach {
                        continue;
                    }
                    let v = image.get(x as u32, y as u32) as f64;
                    peak = peak.max(v);
                    if across.abs() > reach - 1.0 {
                        edge = edge.max(v);
                    }
                    (sum, first, second) = (sum + v, first + v * across, second + v * across * across);
                }
            }
            // Clear of other light: dark at the reach.
            if edge > 0.01 * peak {
                return None;
            }
            let mean = first / sum;
            let px = nalgebra::Vector2::new(t.pixel[0], t.pixel[1]);
            let distance = (nalgebra::Point3::from(t.xyz) - camera.pixel_to_ray(&px)?.origin).norm();
            let defocus = camera.defocus_sigma_px(&px, distance, optics)?;
            Some((second / sum - mean * mean, (px - nalgebra::Vector2::new(511.5, 511.5)).norm(), defocus))
        })
        .collect()
}

/// For the stripe in the room rendered through the lens focused at 91 mm (σ of defocus
/// 0.33–0.64 px over it), and at the points whose defocus is that of a uniform σ 0.4 and 0.6 px:
/// (that σ, the points, the mean and the largest difference of its variance across from the
/// uniform render's (px²), the mean difference between the two uniform renders there (px²)).
fn focused_against_uniform(speckle: bool) -> Vec<(f64, usize, f64, f64, f64)> {
    let (sensor, scene) = room();
    let alpha = 10f64.to_radians();
    let focused = lens(Some(91.0), speckle);
    let Imaging::Lens { optics, .. } = focused.imaging else { unreachable!() };
    let across = |opts: &RenderOptions| {
        let frame = render_laser_frame(&sensor, &scene, alpha, 0, &[0], opts);
        variances_across(&sensor, &scene, alpha, &frame, &optics, 8.0)
    };
    let uniform = |sigma: f64| {
        let flat = Optics { defocus_px: 4.0 * sigma, focus_mm: None, ..optics };
        across(&RenderOptions { imaging: Imaging::Lens { optics: flat, speckle }, ..focused.clone() })
    };
    let field = across(&focused);
    let (lo, hi) = (uniform(0.4), uniform(0.6));
    [(0.4, &lo, &hi), (0.6, &hi, &lo)]
        .into_iter()
        .map(|(sigma, reference, other)| {
            let (mut n, mut sum, mut worst, mut apart) = (0, 0.0, 0.0f64, 0.0);
            for ((f, u), o) in field.iter().zip(reference.iter()).zip(other.iter()) {
                let (Some((f, _, d)), Some((u, _, _)), Some((o, _, _))) = (f, u, o) else { continue };
                if (d - sigma).abs() <= 0.02 {
                    (n, sum, worst, apart) = (n + 1, sum + (f - u), worst.max((f - u).abs()), apart + (o - u).abs());
                }
            }
            let (mean, apart) = (sum / n as f64, apart / n as f64);
            eprintln!(
                "speckle {speckle}, defocus σ {sigma} px: {n} points, focused − uniform {mean:+.4} px² (at most \
                 {worst:.4}), the other uniform render {apart:.4} px² apart"
            );
            (sigma, n, mean, worst, apart)
        })
        .collect()
}

/// Focused at 91 mm, each point of the stripe is as wide as the stripe rendered with one defocus
/// for the whole frame equal to that point's: imaged incoherently, its variance across agrees
/// with that render's within 0.01 px² on average and 0.05 px² at every point, where the two
/// uniform renders (σ 0.4 and 0.6 px) differ by 0.18 px².
#[test]
fn a_focused_lens_blurs_each_point_of_the_stripe_by_its_own_defocus() {
    for (sigma, n, mean, worst, apart) in focused_against_uniform(false) {
        assert!(
            n >= 30 && mean.abs() <= 0.01 && worst <= 0.05 && apart > 0.15,
            "σ {sigma} px: {n} points, {mean:+.4} px² (at most {worst:.4}), apart {apart:.4}"
        );
    }
}

/// The same through the coherent imager, each tile with the pupil of its own light's defocus:
/// under speckle (16 patterns), the mean agrees within 0.03 px² where the uniform renders differ
/// by 0.15 px² or more.
#[test]
fn the_coherent_imager_defocuses_each_tile_by_its_own_light() {
    for (sigma, n, mean, _, apart) in focused_against_uniform(true) {
        assert!(
            n >= 30 && mean.abs() <= 0.03 && apart > 0.15,
            "σ {sigma} px: {n} points, {mean:+.4} px², apart {apart:.4}"
        );
    }
}

/// A focus distance needs the mirror's geometry: a fitted model is refused naming the field, and
/// a focus that blurs part of the image beyond what the renderer images is refused with where.
#[test]
fn a_focus_distance_is_checked_against_the_camera() {
    let (sensor, _) = room();
    let focused = lens(Some(91.0), true);
    focused.check_sensor(&sensor).unwrap();
    let near = lens(Some(60.0), true).check_sensor(&sensor).unwrap_err();
    assert!(
        near.contains("optics.focus_mm (60 mm)") && near.contains("24 px") && near.contains("focus farther"),
        "{near}"
    );
    let far = lens(Some(400.0), true).check_sensor(&sensor).unwrap_err();
    assert!(far.contains("focus nearer"), "{far}");
    let mei = omni_model::MeiParams {
        xi: 0.9,
        fx_px: 300.0,
        fy_px: 300.0,
        cx_px: 255.5,
        cy_px: 255.5,
        k1: 0.0,
        k2: 0.0,
        p1: 0.0,
        p2: 0.0,
        width: 512,
        height: 512,
        inner_radius_px: 20.0,
        outer_radius_px: 250.0,
        viewpoint_mm: [0.0; 3],
    };
    let fitted = Sensor { camera: Box::new(omni_model::MeiCamera::new(mei).unwrap()), transmitter: sensor.transmitter };
    let e = focused.check_sensor(&fitted).unwrap_err();
    assert!(e.contains("optics.focus_mm") && e.contains("hyperbolic"), "{e}");
    lens(None, true).check_sensor(&fitted).unwrap();
}
