//! Held-out validation and warnings about a calibration.
//!
//! [`k_fold`]: the usable images are split into `folds` groups (image k goes to group k mod
//! folds); each group's boards are posed (intrinsics fixed) under the model fitted to the other
//! groups, and their corners' reprojection errors pooled into a test RMS, as BabelCalib reports
//! it. All RMS values here are per corner (Euclidean: √(mean of dx² + dy²)), the convention of
//! OpenCV and Kalibr.

use super::{Calibration, ModelKind, Observation, Options, calibrate};
use crate::pose::estimate_board_pose;
use nalgebra::{Point3, Vector2};

/// Test and training RMS of a k-fold validation (per corner, px).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HeldOut {
    pub folds: usize,
    /// RMS over the held-out images' corners, each image posed under the model of the others.
    pub test_rms_px: f64,
    /// RMS of the folds' own fits over their training corners (pooled).
    pub train_rms_px: f64,
    /// Held-out corners that were compared.
    pub test_corners: usize,
}

/// Fewest usable images for a calibration without a warning.
pub const MIN_IMAGES: usize = 6;

/// The k-fold test RMS (see the module docs); needs at least 2 folds and 2 images per training set.
pub fn k_fold(width: u32, height: u32, obs: &[Observation], opts: &Options, folds: usize) -> Result<HeldOut, String> {
    let usable: Vec<&Observation> =
        obs.iter().filter(|o| o.pixels.len() >= opts.min_corners && o.pixels.len() == o.board_mm.len()).collect();
    if folds < 2 || usable.len() < folds + 2 {
        return Err(format!(
            "{folds}-fold validation needs at least {} usable images, have {}",
            folds + 2,
            usable.len()
        ));
    }
    let (mut test_sq, mut test_n, mut train_sq, mut train_n) = (0.0, 0usize, 0.0, 0usize);
    for f in 0..folds {
        let (train, test): (Vec<_>, Vec<_>) = usable.iter().enumerate().partition(|(k, _)| k % folds != f);
        let train: Vec<Observation> = train.into_iter().map(|(_, o)| (*o).clone()).collect();
        let cal = calibrate(width, height, &train, opts)?;
        let corners: usize = cal.images.iter().filter(|i| i.used).map(|i| i.corners).sum();
        train_sq += cal.rms_per_corner_px().powi(2) * corners as f64;
        train_n += corners;
        let cam = cal.spec.build()?;
        let sign = if cal.mirrored_labels { -1.0 } else { 1.0 };
        for (_, o) in test {
            let board: Vec<[f64; 2]> = o.board_mm.iter().map(|p| [sign * p[0], p[1]]).collect();
            let Some(pose) = estimate_board_pose(cam.as_ref(), &board, &o.pixels) else { continue };
            for (xy, px) in board.iter().zip(&o.pixels) {
                if let Some(q) = cam.point_to_pixel(&(pose * Point3::new(xy[0], xy[1], 0.0))) {
                    test_sq += (q - Vector2::new(px[0], px[1])).norm_squared();
                    test_n += 1;
                }
            }
        }
    }
    if test_n == 0 {
        return Err("no held-out board could be posed".into());
    }
    Ok(HeldOut {
        folds,
        test_rms_px: (test_sq / test_n as f64).sqrt(),
        train_rms_px: (train_sq / train_n.max(1) as f64).sqrt(),
        test_corners: test_n,
    })
}

/// What the user should know about a calibration: too few images, a hyperbolic fit that does
/// not match its mirror.
pub fn warnings(cal: &Calibration, opts: &Options) -> Vec<String> {
    let mut out = Vec::new();
    let used = cal.images.iter().filter(|i| i.used).count();
    if used < MIN_IMAGES {
        out.push(format!(
            "only {used} usable board images (fewer than {MIN_IMAGES}): the intrinsics are poorly constrained; take more pictures all around the mirror"
        ));
    }
    let rms = cal.rms_per_corner_px();
    if opts.model == ModelKind::Hyperbolic && rms > 1.0 {
        out.push(format!(
            "the hyperbolic model with this mirror leaves {rms:.2} px RMS per corner (above 1 px): the mirror (--mirror) does not match or the camera is off its focus; use --model mei"
        ));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::receiver::tests::{real_observations, synthetic_boards};
    use omni_model::{HyperbolicCamera, HyperbolicParams};

    /// On corners with 0.1 px noise per coordinate the per-corner RMS is about 0.1·√2 minus what
    /// the fit absorbs; held-out images, which the fit did not see, come out no better.
    #[test]
    fn k_fold_test_rms_is_the_noise_level_and_not_below_training() {
        let truth = HyperbolicCamera::new(HyperbolicParams::paper()).unwrap();
        let obs: Vec<Observation> = synthetic_boards(&truth, 12, 0.1, 21).into_iter().map(|b| b.0).collect();
        let opts = Options::default();
        let h = k_fold(1024, 1024, &obs, &opts, 4).unwrap();
        eprintln!("synthetic 4-fold: test {:.4} px, training {:.4} px per corner", h.test_rms_px, h.train_rms_px);
        assert!(h.train_rms_px > 0.11 && h.train_rms_px < 0.15, "{h:?}");
        assert!(h.test_rms_px >= h.train_rms_px && h.test_rms_px < 0.2, "{h:?}");
        assert!(k_fold(1024, 1024, &obs[..4], &opts, 4).unwrap_err().contains("at least 6 usable images"));
    }

    #[test]
    fn real_miniomni_set_test_rms_beside_training() {
        let (obs, _) = real_observations();
        let opts = Options::default();
        let cal = calibrate(752, 480, &obs, &opts).unwrap();
        let h = k_fold(752, 480, &obs, &opts, 5).unwrap();
        eprintln!(
            "MiniOmni mei 5-fold: test {:.4} px, folds' training {:.4} px, full fit {:.4} px per corner ({} held-out corners)",
            h.test_rms_px,
            h.train_rms_px,
            cal.rms_per_corner_px(),
            h.test_corners
        );
        assert!(
            h.test_rms_px >= 0.9 * h.train_rms_px && h.test_rms_px < 3.0 * cal.rms_per_corner_px().max(0.1),
            "{h:?}"
        );
        assert!(h.test_corners > 500, "{h:?}");
    }

    #[test]
    fn warnings_for_few_images_and_a_mismatched_mirror() {
        let truth = HyperbolicCamera::new(HyperbolicParams::paper()).unwrap();
        let obs: Vec<Observation> = synthetic_boards(&truth, 5, 0.05, 4).into_iter().map(|b| b.0).collect();
        let opts = Options::default();
        let cal = calibrate(1024, 1024, &obs, &opts).unwrap();
        let w = warnings(&cal, &opts);
        assert_eq!(w.len(), 1, "{w:?}");
        assert!(w[0].contains("only 5 usable board images (fewer than 6)"), "{w:?}");
        // 8 images through a much flatter mirror than the truth (ξ 0.36 for 0.99): the hyperbolic fit cannot follow.
        let obs: Vec<Observation> = synthetic_boards(&truth, 8, 0.05, 9).into_iter().map(|b| b.0).collect();
        let mut mirror = HyperbolicParams::paper();
        mirror.b_mm *= 10.0;
        let opts = Options { model: ModelKind::Hyperbolic, mirror, ..Default::default() };
        let cal = calibrate(1024, 1024, &obs, &opts).unwrap();
        let w = warnings(&cal, &opts);
        eprintln!("mismatched mirror: {:.3} px per corner; {w:?}", cal.rms_per_corner_px());
        assert!(w.iter().any(|m| m.contains("use --model mei")), "{w:?}");
        let good =
            calibrate(1024, 1024, &obs, &Options { model: ModelKind::Hyperbolic, ..Default::default() }).unwrap();
        assert!(warnings(&good, &Options { model: ModelKind::Hyperbolic, ..Default::default() }).is_empty());
    }
}
