//! Property tests of the sensor models (issue 2): camera round trips, light-plane geometry and
//! exact triangulation.

use omni_geom::{Point3, Vector2, Vector3, intersect_ray_plane};
use omni_model::{CameraModel, HyperbolicCamera, HyperbolicParams, Transmitter, TransmitterParams};
use proptest::prelude::*;

fn paper_camera() -> HyperbolicCamera {
    HyperbolicCamera::new(HyperbolicParams::paper()).unwrap()
}

/// project(unproject(px)) over a dense grid covering the whole mirror image: ≤ 1e-9 px.
#[test]
fn pixel_round_trip_over_the_whole_mirror_image() {
    let cam = paper_camera();
    let circle = cam.mirror_circle();
    let mut worst = 0.0f64;
    let mut n = 0;
    let step = 4.0;
    let mut y = 0.0;
    while y < 1024.0 {
        let mut x = 0.0;
        while x < 1024.0 {
            let px = Vector2::new(x + 0.37, y + 0.61);
            if let Some(ray) = cam.pixel_to_ray(&px) {
                for range in [150.0, 1000.0, 20_000.0] {
                    let back = cam.point_to_pixel(&ray.at(range)).expect("visible");
                    worst = worst.max((back - px).norm());
                }
                n += 1;
            } else {
                let r = (px - circle.centre).norm();
                // Only pixels outside the annulus (allowing for the grid step) may be invisible.
                assert!(r < circle.inner_radius + 1.0 || r > circle.outer_radius - 1.0, "{px} r={r}");
            }
            x += step;
        }
        y += step;
    }
    assert!(n > 40_000, "grid covered {n} mirror pixels");
    assert!(worst < 1e-9, "worst pixel round trip {worst:e} px");
    eprintln!("pixel round trip: {n} pixels × 3 ranges, worst {worst:e} px");
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(4000))]

    /// unproject(project(P)) returns P's direction from the viewpoint within 1e-12 rad.
    #[test]
    fn direction_round_trip_all_around(az in 0.0..std::f64::consts::TAU, el in -1.45f64..0.62, range in 120.0f64..30_000.0) {
        let cam = paper_camera();
        let f = cam.viewpoint();
        let d = Vector3::new(el.cos() * az.cos(), el.cos() * az.sin(), el.sin());
        let p = f + d * range;
        if let Some(px) = cam.point_to_pixel(&p) {
            let ray = cam.pixel_to_ray(&px).unwrap();
            let angle = ray.dir.cross(&d).norm().atan2(ray.dir.dot(&d));
            prop_assert!(angle < 1e-12, "angle {angle:e} rad at az {az} el {el}");
            prop_assert!((ray.origin - f).norm() < 1e-12);
        } else {
            // Invisible only beyond the rim (≈ +37°) or in the blind centre (mirror radius < 4 mm,
            // below ≈ −43°).
            prop_assert!(!(-0.74..=0.6).contains(&el), "el {el} not visible");
        }
    }

    /// A point on a light plane (within the 2 m working range), seen through the camera and
    /// triangulated back, is the point within 1e-9 mm.
    #[test]
    fn light_plane_point_triangulates_back(alpha_deg in 0.0f64..30.0, s in -400.0f64..400.0, t in 150.0f64..2000.0, laser in 0usize..2) {
        let cam = paper_camera();
        let tx = Transmitter::new(TransmitterParams::paper()).unwrap();
        let lp = tx.light_plane(alpha_deg.to_radians(), 0, laser).unwrap();
        // A point in the lit half-plane: t along the outgoing central ray, s along the fan axis.
        let p = lp.facet_point + lp.out_dir.into_inner() * t + Vector3::y() * s;
        prop_assert!(lp.plane.signed_distance(&p).abs() < 1e-9);
        prop_assert!(lp.lights(&p));
        if let Some(px) = cam.point_to_pixel(&p) {
            let ray = cam.pixel_to_ray(&px).unwrap();
            if let Ok(hit) = intersect_ray_plane(&ray, &lp.plane, 0.02) {
                prop_assert!((hit.point - p).norm() < 1e-9, "error {:e} mm", (hit.point - p).norm());
            }
        }
    }
}

/// Laser 1 (point-symmetric through the polygon axis) gives the same slope and the mirrored
/// intercept about the axis height: z + h = s·x − b(α).
#[test]
fn second_laser_is_the_point_mirror_of_the_first() {
    let tx = Transmitter::new(TransmitterParams::paper()).unwrap();
    for i in 0..60 {
        let alpha = (0.5 * i as f64).to_radians();
        let (s0, b0) = tx.light_plane(alpha, 3, 0).unwrap().slope_intercept();
        let (s1, b1) = tx.light_plane(alpha, 3, 1).unwrap().slope_intercept();
        assert!((s0 - s1).abs() < 1e-12);
        assert!(((b0 + 120.0) + (b1 + 120.0)).abs() < 1e-10, "{b0} {b1}");
        let lp1 = tx.light_plane(alpha, 3, 1).unwrap();
        assert!(lp1.lights(&Point3::new(-800.0, 0.0, s1 * -800.0 + b1)));
        assert!(!lp1.lights(&Point3::new(800.0, 0.0, s1 * 800.0 + b1)));
    }
}
