//! Held-out validation and warnings about a calibration.
//!
//! [`k_fold`]: the usable images are split into `folds` groups (image k goes to group k mod
//! folds); each group's boards are posed (intrinsics fixed) under the model fitted to the other
//! groups, and their corners' reprojection errors pooled into a test RMS, as BabelCalib reports
//! it. All RMS values here are per corner (Euclidean: √(mean of dx² + dy²)), the convention of
//! OpenCV and Kalibr.
//!
//! [`compare_with_mei`]: a polynomial or central hyperbolic fit is repeated with the Mei model
//! on the same images; if the Mei model fits them [`MODEL_CHECK_RATIO`] times better (per-corner
//! RMS), the chosen model has a systematic error the board poses partly absorbed (a camera off
//! the mirror's focus or tilted: the image is no longer symmetric about one centre), and
//! [`warnings`] says so with the two models' ray difference and names the model to use.

use super::{Calibration, Fit, ModelKind, Observation, Options, calibrate, describe, image_residuals, joint_fit, rms};
use crate::pose::estimate_board_pose;
use nalgebra::{Point3, Vector2, Vector3};
use omni_formats::CameraSpec;
use omni_model::CameraModel;

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

/// A fitted model warns when its per-corner RMS exceeds the Mei model's on the same images by
/// this factor.
pub const MODEL_CHECK_RATIO: f64 = 1.15;

/// The fitted model against a Mei model fitted to the same images (per-corner RMS, px) and how
/// far apart their rays are over the annulus (deg, after the best common rotation: the board
/// poses cannot observe one).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ModelCheck {
    pub model_rms_px: f64,
    pub mei_rms_px: f64,
    pub ray_median_deg: f64,
    pub ray_max_deg: f64,
}

impl ModelCheck {
    /// The fitted model's RMS over the Mei model's.
    pub fn ratio(&self) -> f64 {
        self.model_rms_px / self.mei_rms_px.max(1e-12)
    }

    pub fn to_json(&self) -> serde_json::Value {
        serde_json::json!({
            "model_rms_per_corner_px": self.model_rms_px,
            "mei_rms_per_corner_px": self.mei_rms_px,
            "ray_difference_median_deg": self.ray_median_deg,
            "ray_difference_max_deg": self.ray_max_deg,
        })
    }
}

/// Fits the Mei model (all 9 intrinsics, from `start`'s model and poses) to the images `used` of
/// `sub` that `fit` kept, without rejecting any, and compares it with `fit` (whose camera is
/// `spec`). `None` if the Mei fit fails.
pub(super) fn compare_with_mei(
    start: &Fit,
    fit: &Fit,
    sub: &[Observation],
    used: &[usize],
    spec: &CameraSpec,
    width: u32,
    height: u32,
    opts: &Options,
) -> Option<ModelCheck> {
    let used: Vec<usize> = used.iter().copied().filter(|&k| start.poses[k].is_some()).collect();
    let obs: Vec<Observation> = used.iter().map(|&k| sub[k].clone()).collect();
    let mut mei = start.model.clone();
    mei.kind = ModelKind::Mei;
    mei.free = (0..9).collect();
    mei.non_central = None;
    let keep_all = Options { outlier_factor: f64::INFINITY, ..opts.clone() };
    let mei = joint_fit(mei, &obs, used.iter().map(|&k| start.poses[k]).collect(), &keep_all)?;
    let residuals = |f: &Fit, poses: &[Option<[f64; 6]>], obs: &[Observation]| {
        let mut all = Vec::new();
        for (o, p) in obs.iter().zip(poses) {
            let mut r = vec![0.0; 2 * o.pixels.len()];
            image_residuals(&f.model, &f.model.full, &(*p)?, o, &mut r);
            all.extend(r);
        }
        Some(rms(&all) * std::f64::consts::SQRT_2)
    };
    let mei_rms = residuals(&mei, &mei.poses, &obs)?;
    let model_poses: Vec<Option<[f64; 6]>> = used.iter().map(|&k| fit.poses[k]).collect();
    let model_rms = residuals(fit, &model_poses, &obs)?;
    let mei_opts = Options { model: ModelKind::Mei, ..opts.clone() };
    let (_, _, _, mei_spec) = describe(&mei.model, &[f64::NAN; 9], width, height, &mei_opts);
    let (a, b) = (spec.build().ok()?, mei_spec.build().ok()?);
    let centre = a.mirror_circle().centre;
    let (r_min, r_max) = match opts.annulus {
        Some(an) => (an[2] + 0.5, an[3] - 0.5),
        None => obs.iter().flat_map(|o| &o.pixels).fold((f64::INFINITY, 0.0f64), |(lo, hi), px| {
            let r = (px[0] - centre.x).hypot(px[1] - centre.y);
            (lo.min(r), hi.max(r))
        }),
    };
    let (ray_median_deg, ray_max_deg) =
        ray_difference_deg(a.as_ref(), b.as_ref(), [centre.x, centre.y], r_min, r_max).unwrap_or((f64::NAN, f64::NAN));
    Some(ModelCheck { model_rms_px: model_rms, mei_rms_px: mei_rms, ray_median_deg, ray_max_deg })
}

/// Angle (deg) between the ray directions of two cameras on a polar grid of pixels (40 radii in
/// [r_min, r_max] × 72 azimuths about `centre`) seen by both, after the rotation that best aligns
/// them (Kabsch): (median, max); `None` if fewer than 100 pixels are seen by both.
pub fn ray_difference_deg(
    a: &dyn CameraModel,
    b: &dyn CameraModel,
    centre: [f64; 2],
    r_min: f64,
    r_max: f64,
) -> Option<(f64, f64)> {
    let mut pairs: Vec<(Vector3<f64>, Vector3<f64>)> = Vec::new();
    for k in 0..40 {
        let r = r_min + (r_max - r_min) * k as f64 / 39.0;
        for m in 0..72 {
            let phi = m as f64 * std::f64::consts::TAU / 72.0;
            let px = Vector2::new(centre[0] + r * phi.cos(), centre[1] + r * phi.sin());
            if let (Some(ra), Some(rb)) = (a.pixel_to_ray(&px), b.pixel_to_ray(&px)) {
                pairs.push((rb.dir.into_inner(), ra.dir.into_inner()));
            }
        }
    }
    if pairs.len() < 100 {
        return None;
    }
    let h = pairs.iter().fold(nalgebra::Matrix3::zeros(), |h, (x, y)| h + x * y.transpose());
    let svd = h.svd(true, true);
    let (u, vt) = (svd.u?, svd.v_t?);
    let mut rot = vt.transpose() * u.transpose();
    if rot.determinant() < 0.0 {
        let mut v = vt.transpose();
        v.column_mut(2).neg_mut();
        rot = v * u.transpose();
    }
    let mut errs: Vec<f64> = pairs.iter().map(|(x, y)| (rot * x).angle(y).to_degrees()).collect();
    errs.sort_by(|a, b| a.total_cmp(b));
    Some((errs[errs.len() / 2], errs[errs.len() - 1]))
}

/// Each parameter's leave-one-image-out jackknife σ about `cal` (fitted to `obs` with `opts`):
/// the fit repeated without each image `cal` used, √((g − 1)/g · Σ(θₖ − θ̄)²) over the g fits,
/// in `cal.param_names`' order. Errors when a fit fails or names its parameters otherwise.
pub fn jackknife(
    width: u32,
    height: u32,
    obs: &[Observation],
    opts: &Options,
    cal: &Calibration,
) -> Result<Vec<f64>, String> {
    let used: Vec<usize> = (0..obs.len()).filter(|&k| cal.images.get(k).is_some_and(|i| i.used)).collect();
    if used.len() < 3 {
        return Err(format!("the jackknife needs at least 3 used images, have {}", used.len()));
    }
    let refit = Options { compare_models: false, ..opts.clone() };
    let mut values: Vec<Vec<f64>> = Vec::with_capacity(used.len());
    for &k in &used {
        let others: Vec<Observation> =
            obs.iter().enumerate().filter(|&(j, _)| j != k).map(|(_, o)| o.clone()).collect();
        let c =
            calibrate(width, height, &others, &refit).map_err(|e| format!("jackknife without {}: {e}", obs[k].name))?;
        if c.param_names != cal.param_names {
            return Err(format!("jackknife without {}: the fit has other parameters", obs[k].name));
        }
        values.push(c.params);
    }
    Ok((0..cal.params.len())
        .map(|i| {
            let leave_outs: Vec<f64> = values.iter().map(|v| v[i]).collect();
            omni_geom::stats::jackknife_sigma(&leave_outs).unwrap_or(f64::NAN)
        })
        .collect())
}

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
        let cal = calibrate(width, height, &train, &Options { compare_models: false, ..opts.clone() })?;
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
/// not match its mirror, a model that fits clearly worse than the Mei model (see the module docs).
pub fn warnings(cal: &Calibration, opts: &Options) -> Vec<String> {
    let mut out = Vec::new();
    let used = cal.images.iter().filter(|i| i.used).count();
    if used < MIN_IMAGES {
        out.push(format!(
            "only {used} usable board images (fewer than {MIN_IMAGES}): the intrinsics are poorly constrained; take more pictures all around the mirror"
        ));
    }
    let rms = cal.rms_per_corner_px();
    let mismatched_mirror = opts.model == ModelKind::Hyperbolic && rms > 1.0;
    if mismatched_mirror {
        out.push(format!(
            "the hyperbolic model with this mirror leaves {rms:.2} px RMS per corner (above 1 px): the mirror (--mirror) does not match or the camera is off its focus; use --model mei"
        ));
    }
    // (Beyond 1 px the hyperbolic model's mirror is in doubt, and the warning above says so.)
    if let Some(c) = &cal.model_check
        && c.ratio() > MODEL_CHECK_RATIO
        && !mismatched_mirror
    {
        let ratio = format!(
            "the {} model leaves {:.3} px RMS per corner where the Mei model leaves {:.3} px on the same images ({:.1} ×)",
            opts.model.name(),
            c.model_rms_px,
            c.mei_rms_px,
            c.ratio()
        );
        let rays =
            format!("the two models' rays differ by {:.2}° (median), {:.2}° (max)", c.ray_median_deg, c.ray_max_deg);
        out.push(match opts.model {
            ModelKind::Hyperbolic | ModelKind::Ocam => {
                let (name, fix) = match opts.model {
                    ModelKind::Hyperbolic => ("hyperbolic", "use --model mei, or --model hyperbolic --non-central"),
                    _ => ("ocam", "use --model mei"),
                };
                format!(
                    "{ratio}: the camera is probably off the mirror's focus or tilted, which the {name} model cannot follow; {rays}; {fix}"
                )
            }
            // An ordinary camera's lens distorts more than the pinhole/fisheye polynomial follows
            // (or the camera is catadioptric).
            _ => format!(
                "{ratio}: the lens distorts in a way the {} model cannot follow (a wide-angle or catadioptric camera); {rays}; use --model mei{}",
                opts.model.name(),
                if opts.model == ModelKind::Fisheye { "" } else { " or --model fisheye" }
            ),
        });
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
