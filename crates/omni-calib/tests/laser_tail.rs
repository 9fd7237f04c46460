//! The laser's cross-section measured from stripe frames (`omni_calib::laser_tail`): on rendered
//! frames of known tailed sheets, and on the real hand-held laser's photographs.

use omni_calib::laser_tail::{FrameTail, TailOptions, combine, measure_frame, measure_frames};
use omni_vision::colour::{Channel, Colour, ColourSpec};
use omni_vision::stripe::{RidgeDetector, RidgeParams};
use std::path::PathBuf;

fn real_dir() -> PathBuf {
    PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../../../shared/data/real-laser-handheld"))
}

/// A frame's figures, for the test's log.
fn print(f: &FrameTail) {
    eprintln!("{f:?}");
}

/// The real hand-held laser's frames (../shared/data/real-laser-handheld, im1-im17: the stripe
/// across a checkerboard, 7-15 px wide; sRGB-encoded, so these figures are of encoded values,
/// heavier than the light's). Most frames' windows across the stripe hold the board's squares,
/// are brighter than the laser contrast reads in proportion, or fit without a tail; the two
/// measured, 2026-12-06: im7 (0.25, 1.5 σ), im15 (0.21, 1.4). An independent measurement of
/// 2026-12-03 (numpy, per column, docs/DECISIONS.md) gave shares 0.14-0.20 and lengths 0.7-6 σ
/// over six frames. Asserted: at least two frames measured, each share within 0.12-0.32 and the
/// median within 0.15-0.25, lengths within 1-8 σ.
#[test]
fn real_frames_give_a_tail_like_the_independent_measurement() {
    let spec = ColourSpec { channel: Channel::Laser(Colour::Red), bayer: None, sites: false };
    let paths: Vec<PathBuf> = (1..=17).map(|k| real_dir().join(format!("im{k}.png"))).collect();
    let ridge = RidgeParams { max_width: 30.0, ..Default::default() };
    let t0 = std::time::Instant::now();
    let report = measure_frames(&paths, &spec, &ridge, &TailOptions::default()).unwrap();
    eprintln!("measured in {:.1} s", t0.elapsed().as_secs_f64());
    report.frames.iter().for_each(print);
    for s in &report.skipped {
        eprintln!("skipped {}: {}", s.name, s.reason);
    }
    eprintln!("median share {:.3}, length {:.2} σ", report.tail_weight, report.tail_length);
    assert!(report.frames.len() >= 2, "{} frames measured", report.frames.len());
    for f in &report.frames {
        assert!((0.12..=0.32).contains(&f.tail_weight), "{}: share {}", f.name, f.tail_weight);
        assert!((1.0..=8.0).contains(&f.tail_length), "{}: length {}", f.name, f.tail_length);
    }
    assert!((0.15..=0.25).contains(&report.tail_weight), "median share {}", report.tail_weight);
}

mod rendered {
    use super::*;
    use nalgebra::{Rotation3, UnitQuaternion, Vector3};
    use omni_formats::scene::{SceneFile, SceneObject, Shape};
    use omni_geom::rng::SplitMix64;
    use omni_geom::{Plane, Point3};
    use omni_simulator::{RenderOptions, Scene, Sensor, SheetProfile, render_laser_frame};
    use omni_vision::image_io::GrayImage;

    /// The stopped polygon's mirror angle (rad), as in the fixed-plane tests.
    const ALPHA: f64 = 0.4;

    /// A plain white target 600 × 450 mm facing the viewpoint, `d` mm out along the light plane.
    fn target(plane: &Plane, d: f64, rng: &mut SplitMix64) -> SceneObject {
        let azimuth = (rng.uniform() - 0.5) * 40f64.to_radians();
        let (x, y) = (d * azimuth.cos(), d * azimuth.sin());
        let n = plane.normal;
        let z = (plane.offset - n.x * x - n.y * y) / n.z;
        let viewpoint = Point3::new(0.0, 0.0, 80.0);
        let centre = Point3::new(x, y, z);
        let facing = (viewpoint - centre).normalize();
        let tilt = UnitQuaternion::from_euler_angles((rng.uniform() - 0.5) * 0.5, (rng.uniform() - 0.5) * 0.5, 0.0);
        let normal = tilt * facing;
        let up = Rotation3::rotation_between(&Vector3::x(), &normal).map_or(Vector3::z(), |_| Vector3::z());
        SceneObject {
            name: Some("target".into()),
            albedo: 0.8,
            texture: None,
            shape: Shape::Rectangle {
                centre_mm: centre.coords.into(),
                normal: normal.into(),
                up: up.into(),
                width_mm: 600.0,
                height_mm: 450.0,
            },
        }
    }

    fn measure(profile: SheetProfile, fwhm: f64, frames: usize, seed: u64) -> Vec<FrameTail> {
        let sensor = Sensor::paper();
        let lp = sensor.transmitter.light_plane(ALPHA, 0, 0).expect("laser 0");
        let plane = if lp.plane.offset < 0.0 { lp.plane.flipped() } else { lp.plane };
        let mut rng = SplitMix64::new(seed);
        let opts = RenderOptions { profile, stripe_fwhm_px: Some(fwhm), seed, ..RenderOptions::ideal() };
        let blur = opts.imaging.psf_sigma_px();
        (0..frames)
            .filter_map(|k| {
                let d = 180.0 + 150.0 * k as f64 / (frames - 1).max(1) as f64;
                let scene = Scene::from_file(SceneFile::new(vec![target(&plane, d, &mut rng)])).unwrap();
                let frame = render_laser_frame(&sensor, &scene, ALPHA, 0, &[0], &opts);
                let img = GrayImage {
                    width: frame.image.width,
                    height: frame.image.height,
                    bit_depth: 8,
                    data: frame.image.data,
                };
                let params =
                    RidgeParams { max_width: 3.0 * fwhm + 6.0, optics_blur_px: Some(blur), ..Default::default() };
                let det = RidgeDetector::whole_frame(img.width, img.height, params);
                let points = det.detect(&img);
                let tail_opts = TailOptions { blur_px: blur, ..Default::default() };
                match measure_frame(&format!("f{k}"), &img, &points, None, &tail_opts) {
                    Ok(f) => {
                        print(&f);
                        Some(f)
                    }
                    Err(e) => {
                        eprintln!("f{k}: {e}");
                        None
                    }
                }
            })
            .collect()
    }

    /// Tailed sheets of two shapes (the real laser's, 17 % in a tail 4 core σ long, on either
    /// side; and 40 % in one 1.5 σ long), 6 and 10 px wide, on a plain target 180-330 mm out,
    /// ideal optics (the lens's σ 0.7 px known), four frames each (a frame's windows may run off
    /// the target into the mirror's hole and are refused). Asserted: share within 0.015 and
    /// length within 10 % at 6 px; at 10 px, where a wide rendered stripe is a little more
    /// lopsided than its sheet (the oblique view across it), share within 0.04. Measured
    /// figures in docs/DECISIONS.md.
    #[test]
    fn rendered_tailed_sheets_give_back_their_tail() {
        for (w, l, side, fwhm) in
            [(0.17, 4.0, 1, 6.0), (0.17, 4.0, -1, 6.0), (0.4, 1.5, 1, 6.0), (0.17, 4.0, 1, 10.0), (0.4, 1.5, 1, 10.0)]
        {
            let profile = SheetProfile::Tailed { tail_weight: w, tail_length: l, tail_side: side };
            let frames = measure(profile, fwhm, 4, 3);
            let (share, length) = combine(&frames).expect("a frame measured");
            eprintln!(
                "truth ({w}, {l}, side {side}) at {fwhm} px: measured ({share:.3}, {length:.2}) over {} frames",
                frames.len()
            );
            assert!(frames.len() >= 2, "{} frames measured", frames.len());
            let (max_share, max_length) = if fwhm < 8.0 { (0.015, 0.1) } else { (0.04, 0.15) };
            assert!((share - w).abs() <= max_share, "({w}, {l}) at {fwhm} px: share {share}");
            assert!((length / l - 1.0).abs() <= max_length, "({w}, {l}) at {fwhm} px: length {length}");
        }
    }

    /// The paper sensor in a 1.6 × 1.6 × 1.0 m room, one laser: its stripe is a ring about the
    /// mirror's axis, whose normals are turned away from the mirror's centre. Tailed sheet (0.17,
    /// 4) 6 px wide at its middle, two mirror angles. Measured 2026-12-06: (0.184, 1.98 σ) and
    /// (0.195, 2.50 σ), median (0.189, 2.24): the share holds, the length comes out short. The
    /// ring's width changes with the walls' distance around it (5.0 and 5.8 px FWHM against the
    /// 6 px at its middle), and the median of profiles of several widths is not one tailed
    /// profile; a plain target at one distance gives the length within 10 % (above). Asserted:
    /// share within 0.045, length within 1.5-6 σ.
    #[test]
    fn a_ring_about_the_mirrors_axis_gives_back_its_tail() {
        use omni_formats::scene::Shape;
        let sensor = Sensor::paper();
        let room = SceneObject {
            name: Some("room".into()),
            albedo: 0.8,
            texture: None,
            shape: Shape::Room { centre_mm: [0.0, 0.0, 0.0], size_mm: [1600.0, 1600.0, 1000.0] },
        };
        let scene = Scene::from_file(SceneFile::new(vec![room])).unwrap();
        let profile = SheetProfile::Tailed { tail_weight: 0.17, tail_length: 4.0, tail_side: 1 };
        let opts = RenderOptions { profile, stripe_fwhm_px: Some(6.0), seed: 5, ..RenderOptions::ideal() };
        let blur = opts.imaging.psf_sigma_px();
        let mirror = sensor.camera.mirror_circle();
        let frames: Vec<FrameTail> = [16.0f64, 24.0]
            .iter()
            .filter_map(|alpha| {
                let frame = render_laser_frame(&sensor, &scene, alpha.to_radians(), 0, &[0], &opts);
                let img = GrayImage {
                    width: frame.image.width,
                    height: frame.image.height,
                    bit_depth: 8,
                    data: frame.image.data,
                };
                let params = RidgeParams { max_width: 30.0, optics_blur_px: Some(blur), ..Default::default() };
                let points = RidgeDetector::new(img.width, img.height, mirror, params).detect(&img);
                let tail_opts = TailOptions { blur_px: blur, mirror: Some(mirror), ..Default::default() };
                let measured = measure_frame(&format!("alpha {alpha}"), &img, &points, None, &tail_opts);
                match &measured {
                    Ok(f) => print(f),
                    Err(e) => eprintln!("alpha {alpha}: {e}"),
                }
                measured.ok()
            })
            .collect();
        let (share, length) = combine(&frames).expect("a frame measured");
        eprintln!("ring: measured ({share:.3}, {length:.2}) over {} frames", frames.len());
        assert!((share - 0.17).abs() <= 0.045 && (1.5..=6.0).contains(&length), "({share}, {length})");
    }

    /// A Gaussian sheet has no tail to measure: every frame is refused as fitting a Gaussian as
    /// well (none of its tail fits tells a share from a length either).
    #[test]
    fn a_gaussian_sheet_shows_no_tail() {
        let frames = measure(SheetProfile::Gaussian, 6.0, 4, 3);
        assert!(frames.is_empty(), "{} frames measured a tail", frames.len());
    }
}
