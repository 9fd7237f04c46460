//! Receiver calibration: the catadioptric (or an ordinary) camera from checkerboard corners.
//!
//! [`calibrate`] fits one of the models of [`ModelKind`] to the corners of many board images:
//! 1. Initialisation without hand-tuning: principal point at the centre of the mirror rim circle
//!    ([`Options::annulus`], else the image centre), ξ = 1, and the
//!    generalised focal length γ chosen on a logarithmic grid by the median per-image
//!    reprojection error after a linear pose (DLT on the rays) and a short per-board pose
//!    refinement. The same search decides once whether the corner labeling must be mirrored
//!    (a board seen through one mirror appears reversed).
//! 2. Joint Levenberg–Marquardt over the intrinsics and all board poses (6 per board) with a
//!    Huber loss; the Jacobian is numeric but exploits the block structure (a pose moves only its
//!    own board's residuals).
//! 3. Images whose RMS error is an outlier (more than `outlier_factor` × the median and above
//!    `outlier_floor_px`) are rejected with the reason, and the fit is repeated.
//!
//! The polynomial (OCamCalib) model starts from the fitted Mei model (its rays give the
//! polynomial by linear least squares) and is then refined the same way. The exact hyperbolic
//! model is the Mei model with ξ fixed by the given mirror and no distortion; only the focal
//! lengths and the principal point are fitted. With [`Options::non_central`] the camera's offset
//! from the mirror's focus and its tilt are then fitted too, projecting exactly (ray tracing
//! through the mirror, each corner's projection iterated from its observed pixel); its board
//! poses are in the mirror's frame (focus F at (0, 0, 2c)), as the central hyperbolic ones.
//! The hyperbolic camera's blind centre comes from the annulus' inner circle, else it is shrunk
//! (if needed) to keep every observed corner.
//!
//! The ordinary-camera models (pinhole with radial-tangential distortion, Kannala–Brandt
//! fisheye) start from the fitted Mei model too: principal point and aspect from it, focal length
//! and radial distortion by linear least squares on its rays ([`ordinary_from_mei`]).
//!
//! The polynomial, central hyperbolic and ordinary fits are checked against a Mei fit of the same
//! images ([`validate::compare_with_mei`], [`Calibration::model_check`]).
//!
//! [`session`] runs the commands of `omni-calib-receiver` (detection, fit, report, exports,
//! conversions) on top of these.

pub mod convert;
pub mod corners_file;
pub mod export;
pub mod query;
pub mod session;
pub mod validate;
mod yaml;

use crate::pose::{UNPROJECTABLE_PX, board_to_world, params_to_pose, pose_from_rays, pose_to_params, refine_pose};
use nalgebra::{DMatrix, Isometry3, Point3, Vector2, Vector3};
use omni_formats::CameraSpec;
use omni_geom::lm;
use omni_model::fisheye::{kb_intrinsics, kb_project, kb_unproject};
use omni_model::mei::{mei_project, mei_unproject};
use omni_model::ocam::{ocam_project, ocam_unproject};
use omni_model::pinhole::{radtan_intrinsics, radtan_project, radtan_unproject};
use omni_model::{
    CameraModel as _, FisheyeParams, HyperbolicCamera, HyperbolicParams, MeiParams, OcamParams, PinholeParams,
};
use serde_json::json;

/// The camera model to fit.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ModelKind {
    /// Mei's unified model with radial-tangential distortion.
    Mei,
    /// Scaramuzza's polynomial model (OCamCalib).
    Ocam,
    /// The exact hyperbolic mirror model with the mirror (a, b) given.
    Hyperbolic,
    /// An ordinary camera: pinhole with radial-tangential distortion k1 k2 p1 p2 k3 (OpenCV's
    /// `calibrateCamera` default).
    Pinhole,
    /// The same with k3 = 0: k1 k2 p1 p2, Kalibr's `pinhole-radtan`.
    PinholeRadtan,
    /// An ordinary fisheye camera: Kannala–Brandt k1..k4 (OpenCV's `cv::fisheye`, Kalibr's
    /// `pinhole-equi`).
    Fisheye,
}

impl ModelKind {
    /// The name `--model` takes and the report writes.
    pub fn name(self) -> &'static str {
        match self {
            ModelKind::Mei => "mei",
            ModelKind::Ocam => "ocam",
            ModelKind::Hyperbolic => "hyperbolic",
            ModelKind::Pinhole => "pinhole",
            ModelKind::PinholeRadtan => "pinhole-radtan",
            ModelKind::Fisheye => "fisheye",
        }
    }

    /// The ordinary-camera models (pinhole and fisheye), fitted from the Mei model's rays.
    pub fn is_ordinary(self) -> bool {
        matches!(self, ModelKind::Pinhole | ModelKind::PinholeRadtan | ModelKind::Fisheye)
    }
}

impl std::str::FromStr for ModelKind {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "mei" => Ok(ModelKind::Mei),
            "ocam" => Ok(ModelKind::Ocam),
            "hyperbolic" => Ok(ModelKind::Hyperbolic),
            "pinhole" | "opencv-pinhole" => Ok(ModelKind::Pinhole),
            "pinhole-radtan" => Ok(ModelKind::PinholeRadtan),
            "fisheye" | "kannala-brandt" | "pinhole-equi" => Ok(ModelKind::Fisheye),
            _ => Err(format!(
                "unknown model \"{s}\" (known: mei, ocam, hyperbolic, pinhole, pinhole-radtan, fisheye; \
                 aliases opencv-pinhole, kannala-brandt, pinhole-equi)"
            )),
        }
    }
}

/// The corners of one board image.
#[derive(Debug, Clone, PartialEq)]
pub struct Observation {
    /// Image name (for reports).
    pub name: String,
    /// Board coordinates of the corners (mm, board frame z = 0).
    pub board_mm: Vec<[f64; 2]>,
    /// Their image positions (px).
    pub pixels: Vec<[f64; 2]>,
}

impl Observation {
    /// From detected corners: corner (i, j) is at (i·square, j·square) mm on the board.
    pub fn from_corners(name: &str, corners: &omni_vision::corners::BoardCorners, square_mm: f64) -> Self {
        Observation {
            name: name.to_string(),
            board_mm: corners
                .corners
                .iter()
                .map(|c| [c.index[0] as f64 * square_mm, c.index[1] as f64 * square_mm])
                .collect(),
            pixels: corners.corners.iter().map(|c| c.px).collect(),
        }
    }

    /// The same corners with the board mirrored (x → −x): the other labeling handedness.
    pub fn mirrored(&self) -> Observation {
        Observation { board_mm: self.board_mm.iter().map(|p| [-p[0], p[1]]).collect(), ..self.clone() }
    }
}

/// Settings of the fit.
#[derive(Debug, Clone)]
pub struct Options {
    pub model: ModelKind,
    /// Huber threshold of the robust loss (px).
    pub huber_px: f64,
    /// An image is an outlier if its RMS exceeds this factor × the median image RMS …
    pub outlier_factor: f64,
    /// … and this absolute floor (px).
    pub outlier_floor_px: f64,
    /// Degree of the OCamCalib polynomial (a1 is fixed to 0 as in OCamCalib).
    pub ocam_degree: usize,
    /// Mirror for the hyperbolic model (a, b, rim radius; focal length and principal point are
    /// fitted).
    pub mirror: HyperbolicParams,
    /// Fewest corners per image.
    pub min_corners: usize,
    /// LM iterations of the joint refinement.
    pub max_iterations: usize,
    /// Refit once with each image weighted by 1 / (its RMS / the median RMS), clamped to
    /// [0.3, 3]: maximum likelihood when images differ in corner noise.
    pub reweight_images: bool,
    /// The mirror annulus in the image, if known (e.g. the rim circle fitted in an image of a lit
    /// scene): [centre x, centre y, inner radius, outer radius] px. The principal point starts at
    /// its centre, the focal-length search scales with its outer radius, and the fitted Mei and
    /// polynomial models are valid inside it (else in the whole image).
    pub annulus: Option<[f64; 4]>,
    /// For the hyperbolic model: fit the camera's offset from the mirror's focus and its tilt
    /// too (non-central model), after the central fit.
    pub non_central: bool,
    /// For the polynomial and the central hyperbolic model: fit a Mei model to the same images
    /// as well and report both ([`Calibration::model_check`], [`validate::warnings`]).
    pub compare_models: bool,
}

impl Default for Options {
    fn default() -> Self {
        Options {
            model: ModelKind::Mei,
            huber_px: 1.0,
            outlier_factor: 3.0,
            outlier_floor_px: 0.5,
            ocam_degree: 4,
            mirror: HyperbolicParams::paper(),
            min_corners: 8,
            max_iterations: 60,
            reweight_images: true,
            annulus: None,
            non_central: false,
            compare_models: true,
        }
    }
}

/// What happened to one image.
#[derive(Debug, Clone, PartialEq)]
pub struct ImageReport {
    pub name: String,
    pub corners: usize,
    /// RMS reprojection error of the image under the final model (px, per coordinate: x and y
    /// residuals pooled; × √2 per corner), if a pose was found.
    pub rms_px: Option<f64>,
    /// Whether the image took part in the final fit.
    pub used: bool,
    /// Why it was rejected.
    pub reason: Option<String>,
    /// Board → world pose (if found).
    pub pose: Option<Isometry3<f64>>,
}

/// The result of a calibration.
#[derive(Debug, Clone)]
pub struct Calibration {
    /// The fitted camera (ready for `camera.json`).
    pub spec: CameraSpec,
    /// RMS reprojection error over all corners of the used images (px, per coordinate: x and y
    /// residuals pooled; see [`Calibration::rms_per_corner_px`]).
    pub rms_px: f64,
    pub images: Vec<ImageReport>,
    /// Names, values and standard deviations of the fitted intrinsics.
    pub param_names: Vec<String>,
    pub params: Vec<f64>,
    pub std_devs: Vec<f64>,
    /// Whether the corner labeling was mirrored (see [`Observation::mirrored`]).
    pub mirrored_labels: bool,
    /// The fitted model against a Mei model fitted to the same images (polynomial and central
    /// hyperbolic fits with [`Options::compare_models`]): see [`validate::ModelCheck`].
    pub model_check: Option<validate::ModelCheck>,
}

impl Calibration {
    /// RMS reprojection error per corner (Euclidean, px): √2 × [`Calibration::rms_px`], the value
    /// OpenCV and Kalibr print.
    pub fn rms_per_corner_px(&self) -> f64 {
        self.rms_px * std::f64::consts::SQRT_2
    }

    /// Where the fitted model puts the corners of image `k` (the same `obs` as given to
    /// [`calibrate`]); `None` for corners that do not project or images without a pose.
    pub fn reprojected(&self, k: usize, obs: &Observation) -> Vec<Option<[f64; 2]>> {
        let (Some(pose), Ok(cam)) = (self.images.get(k).and_then(|i| i.pose), self.spec.build()) else {
            return vec![None; obs.pixels.len()];
        };
        let sign = if self.mirrored_labels { -1.0 } else { 1.0 };
        obs.board_mm
            .iter()
            .map(|xy| cam.point_to_pixel(&(pose * Point3::new(sign * xy[0], xy[1], 0.0))).map(|p| [p.x, p.y]))
            .collect()
    }

    /// The calibration report stored in `camera.json`.
    pub fn report_json(&self) -> serde_json::Value {
        let params: serde_json::Map<String, serde_json::Value> = self
            .param_names
            .iter()
            .zip(self.params.iter().zip(&self.std_devs))
            .map(|(n, (v, s))| (n.clone(), json!({"value": v, "std": s})))
            .collect();
        let mut report = json!({
            "rms_px": self.rms_px,
            "rms_per_corner_px": self.rms_per_corner_px(),
            "rms_convention": "rms_px: per coordinate (x and y residuals pooled); rms_per_corner_px: per corner, Euclidean (as OpenCV and Kalibr)",
            "images_used": self.images.iter().filter(|i| i.used).count(),
            "images_rejected": self.images.iter().filter(|i| !i.used).count(),
            "mirrored_labels": self.mirrored_labels,
            "model_check": self.model_check.as_ref().map(|c| c.to_json()),
            "parameters": params,
            "images": self.images.iter().map(|i| json!({
                "name": i.name,
                "corners": i.corners,
                "rms_px": i.rms_px,
                "used": i.used,
                "reason": i.reason,
            })).collect::<Vec<_>>(),
        });
        if let CameraSpec::Ocam(p) = &self.spec {
            let [lo, hi] = p.valid_rho_range();
            report["inverse_poly"] = json!({
                "degree": p.inv_poly.len().saturating_sub(1),
                "max_error_px": p.inverse_poly_error_px(),
                "rho_range_px": [lo, hi],
            });
        }
        report
    }
}

/// The model being fitted: which parameters are free, and how to project with them.
#[derive(Debug, Clone)]
struct Model {
    kind: ModelKind,
    /// Full parameter vector (free ones are overwritten from the solver's vector).
    full: Vec<f64>,
    free: Vec<usize>,
    names: Vec<String>,
    /// ρ normalisation of the polynomial coefficients (px).
    rho_scale: f64,
    rho_max: f64,
    /// The non-central hyperbolic model: the mirror, with `full` = [fx, fy, cx, cy (px), camera
    /// offset x, y, z (mm), tilt about x, y (deg)]; world frame of [`omni_model::HyperbolicCamera`].
    non_central: Option<HyperbolicParams>,
}

impl Model {
    fn mei(centre: [f64; 2], xi: f64, gamma: f64, fixed_xi_no_distortion: bool) -> Model {
        let full = vec![xi, gamma, gamma, centre[0], centre[1], 0.0, 0.0, 0.0, 0.0];
        let free = if fixed_xi_no_distortion { vec![1, 2, 3, 4] } else { (0..9).collect() };
        let names =
            ["xi", "fx_px", "fy_px", "cx_px", "cy_px", "k1", "k2", "p1", "p2"].iter().map(|s| s.to_string()).collect();
        Model {
            kind: if fixed_xi_no_distortion { ModelKind::Hyperbolic } else { ModelKind::Mei },
            full,
            free,
            names,
            rho_scale: 1.0,
            rho_max: 0.0,
            non_central: None,
        }
    }

    /// The non-central hyperbolic model started from a fitted central one (`central`: the Mei
    /// vector with ξ of `mirror`): offset and tilt zero, the pinhole focal lengths f = γ·(a² + c²)/b².
    fn non_central(central: &Model, mirror: &HyperbolicParams) -> Model {
        let f = &central.full;
        let k = hyperbolic_focal_factor(mirror);
        let full = vec![f[1] * k, f[2] * k, f[3], f[4], 0.0, 0.0, 0.0, 0.0, 0.0];
        let names = [
            "fx_px",
            "fy_px",
            "cx_px",
            "cy_px",
            "camera_offset_x_mm",
            "camera_offset_y_mm",
            "camera_offset_z_mm",
            "camera_tilt_x_deg",
            "camera_tilt_y_deg",
        ];
        // The fit must not refuse a corner for lying in the blind centre or beyond the rim.
        let mirror =
            HyperbolicParams { inner_radius_mm: 0.0, rim_radius_mm: mirror.rim_radius_mm * 2.0, ..mirror.clone() };
        Model {
            kind: ModelKind::Hyperbolic,
            full,
            free: (0..9).collect(),
            names: names.iter().map(|s| s.to_string()).collect(),
            rho_scale: 1.0,
            rho_max: 0.0,
            non_central: Some(mirror),
        }
    }

    /// The non-central camera of a full vector.
    fn camera(&self, full: &[f64]) -> Option<HyperbolicCamera> {
        let m = self.non_central.as_ref()?;
        HyperbolicCamera::new(HyperbolicParams {
            fx_px: full[0],
            fy_px: full[1],
            cx_px: full[2],
            cy_px: full[3],
            camera_offset_mm: [full[4], full[5], full[6]],
            camera_tilt_deg: [full[7], full[8]],
            ..m.clone()
        })
        .ok()
    }

    /// Smallest finite-difference step of the free parameter at full index `i` (÷ 10⁶): the
    /// offsets (mm) and tilts (deg) start at 0 and need steps well above the projection's
    /// iteration tolerance.
    fn step_floor(&self, i: usize) -> f64 {
        if self.non_central.is_some() && i >= 4 { 1.0 } else { 1e-2 }
    }

    fn free_values(&self) -> Vec<f64> {
        self.free.iter().map(|&i| self.full[i]).collect()
    }

    fn with_free(&self, v: &[f64]) -> Vec<f64> {
        let mut full = self.full.clone();
        for (k, &i) in self.free.iter().enumerate() {
            full[i] = v[k];
        }
        full
    }

    /// OCam full vector: cx, cy, c, d, e, a0, a2·R², a3·R³, … → the model crate's order.
    fn ocam_vector(&self, full: &[f64]) -> Vec<f64> {
        let mut v = full[..5].to_vec();
        v.push(full[5]);
        v.push(0.0);
        for (k, a) in full[6..].iter().enumerate() {
            v.push(a / self.rho_scale.powi(k as i32 + 2));
        }
        v
    }

    /// The central model's intrinsics as the model crate's maps take them (computed once per
    /// parameter vector: the polynomial's scaling, the ordinary models' domain).
    fn prepare(&self, full: &[f64]) -> Vec<f64> {
        match self.kind {
            ModelKind::Mei | ModelKind::Hyperbolic => full.to_vec(),
            ModelKind::Ocam => self.ocam_vector(full),
            ModelKind::Pinhole | ModelKind::PinholeRadtan => radtan_intrinsics(full),
            ModelKind::Fisheye => kb_intrinsics(full),
        }
    }

    /// [`Model::project`] of a central model with [`Model::prepare`]d intrinsics.
    fn project_prepared(&self, prepared: &[f64], d: &Vector3<f64>) -> Option<Vector2<f64>> {
        match self.kind {
            ModelKind::Mei | ModelKind::Hyperbolic => mei_project(prepared, d),
            ModelKind::Ocam => ocam_project(prepared, d, self.rho_max),
            ModelKind::Pinhole | ModelKind::PinholeRadtan => radtan_project(prepared, d),
            ModelKind::Fisheye => kb_project(prepared, d),
        }
    }

    /// Pixel of a viewing direction (central models; for the non-central one the direction seen
    /// from the mirror's focus, at 10 m).
    fn project(&self, full: &[f64], d: &Vector3<f64>) -> Option<Vector2<f64>> {
        if let Some(cam) = self.camera(full) {
            return cam.point_to_pixel(&(cam.viewpoint() + 1e4 * d.normalize()));
        }
        self.project_prepared(&self.prepare(full), d)
    }

    fn unproject(&self, full: &[f64], px: &Vector2<f64>) -> Option<Vector3<f64>> {
        if let Some(cam) = self.camera(full) {
            return cam.pixel_to_ray(px).map(|r| r.dir.into_inner());
        }
        let p = self.prepare(full);
        match self.kind {
            ModelKind::Mei | ModelKind::Hyperbolic => mei_unproject(&p, px),
            ModelKind::Ocam => ocam_unproject(&p, px),
            ModelKind::Pinhole | ModelKind::PinholeRadtan => radtan_unproject(&p, px),
            ModelKind::Fisheye => kb_unproject(&p, px),
        }
    }
}

/// Per-image residuals (2 per corner) for a pose given as 6 parameters.
fn image_residuals(model: &Model, full: &[f64], pose: &[f64], obs: &Observation, out: &mut [f64]) {
    let camera = model.camera(full);
    if model.non_central.is_some() && camera.is_none() {
        out.fill(UNPROJECTABLE_PX);
        return;
    }
    let prepared = if camera.is_none() { model.prepare(full) } else { Vec::new() };
    for (k, (xy, px)) in obs.board_mm.iter().zip(&obs.pixels).enumerate() {
        let p = board_to_world(pose, *xy);
        // The non-central projection iterates from the observed pixel.
        let q = match &camera {
            Some(cam) => cam.project_from(&p, &Vector2::new(px[0], px[1])),
            None => model.project_prepared(&prepared, &p.coords),
        };
        match q {
            Some(q) => {
                out[2 * k] = q.x - px[0];
                out[2 * k + 1] = q.y - px[1];
            }
            None => {
                out[2 * k] = UNPROJECTABLE_PX;
                out[2 * k + 1] = UNPROJECTABLE_PX;
            }
        }
    }
}

fn rms(r: &[f64]) -> f64 {
    (r.iter().map(|x| x * x).sum::<f64>() / r.len().max(1) as f64).sqrt()
}

/// The joint problem: free intrinsics, then 6 pose parameters per image.
struct Joint<'a> {
    model: &'a Model,
    obs: &'a [Observation],
    offsets: Vec<usize>,
    n_res: usize,
    /// Per-image residual weights (1/relative noise level).
    weights: Vec<f64>,
}

impl<'a> Joint<'a> {
    fn new(model: &'a Model, obs: &'a [Observation]) -> Self {
        let mut offsets = Vec::with_capacity(obs.len());
        let mut n = 0;
        for o in obs {
            offsets.push(n);
            n += 2 * o.pixels.len();
        }
        Joint { model, obs, offsets, n_res: n, weights: vec![1.0; obs.len()] }
    }

    fn image_res(&self, k: usize, full: &[f64], pose: &[f64], out: &mut [f64]) {
        image_residuals(self.model, full, pose, &self.obs[k], out);
        if self.weights[k] != 1.0 {
            out.iter_mut().for_each(|r| *r *= self.weights[k]);
        }
    }

    fn n_intr(&self) -> usize {
        self.model.free.len()
    }
}

impl lm::Problem for Joint<'_> {
    fn num_params(&self) -> usize {
        self.n_intr() + 6 * self.obs.len()
    }
    fn num_residuals(&self) -> usize {
        self.n_res
    }
    fn residuals(&self, p: &[f64], out: &mut [f64]) {
        let full = self.model.with_free(&p[..self.n_intr()]);
        for (k, o) in self.obs.iter().enumerate() {
            let pose = &p[self.n_intr() + 6 * k..self.n_intr() + 6 * k + 6];
            let off = self.offsets[k];
            self.image_res(k, &full, pose, &mut out[off..off + 2 * o.pixels.len()]);
        }
    }
    fn jacobian(&self, p: &[f64], jac: &mut DMatrix<f64>) {
        jac.fill(0.0);
        let ni = self.n_intr();
        let mut plus = vec![0.0; self.n_res];
        let mut minus = vec![0.0; self.n_res];
        let mut q = p.to_vec();
        for j in 0..ni {
            let h = 1e-6 * p[j].abs().max(self.model.step_floor(self.model.free[j]));
            q[j] = p[j] + h;
            self.residuals(&q, &mut plus);
            q[j] = p[j] - h;
            self.residuals(&q, &mut minus);
            q[j] = p[j];
            for i in 0..self.n_res {
                jac[(i, j)] = (plus[i] - minus[i]) / (2.0 * h);
            }
        }
        let full = self.model.with_free(&p[..ni]);
        for (k, o) in self.obs.iter().enumerate() {
            let m = 2 * o.pixels.len();
            let off = self.offsets[k];
            let base = ni + 6 * k;
            let mut pose = p[base..base + 6].to_vec();
            for c in 0..6 {
                let h = if c < 3 { 1e-7 } else { 1e-5 * pose[c].abs().max(1.0) };
                let v = pose[c];
                pose[c] = v + h;
                self.image_res(k, &full, &pose, &mut plus[..m]);
                pose[c] = v - h;
                self.image_res(k, &full, &pose, &mut minus[..m]);
                pose[c] = v;
                for i in 0..m {
                    jac[(off + i, base + c)] = (plus[i] - minus[i]) / (2.0 * h);
                }
            }
        }
    }
}

/// Linear + refined pose of one image under a trial model; (pose params, RMS px).
fn initial_pose(model: &Model, full: &[f64], obs: &Observation, iterations: usize) -> Option<([f64; 6], f64)> {
    let mut dirs = Vec::new();
    let mut board = Vec::new();
    for (xy, px) in obs.board_mm.iter().zip(&obs.pixels) {
        if let Some(d) = model.unproject(full, &Vector2::new(px[0], px[1])) {
            dirs.push(d);
            board.push(*xy);
        }
    }
    let pose = pose_from_rays(&Point3::origin(), &dirs, &board)?;
    let project = |p: &Point3<f64>| model.project(full, &p.coords);
    let (pose, rms, _) = refine_pose(&project, &obs.board_mm, &obs.pixels, &pose, iterations);
    Some((pose_to_params(&pose), rms))
}

fn median(mut v: Vec<f64>) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(|a, b| a.total_cmp(b));
    v[v.len() / 2]
}

/// Grid search of γ (and the labeling handedness) for the Mei/hyperbolic model.
fn initialise_mei(
    width: u32,
    height: u32,
    annulus: Option<[f64; 4]>,
    xi: f64,
    fixed: bool,
    obs: &[Observation],
) -> Option<(Model, bool)> {
    let (centre, r) = match annulus {
        Some([cx, cy, _, outer]) => ([cx, cy], outer),
        None => ([(width as f64 - 1.0) / 2.0, (height as f64 - 1.0) / 2.0], width.min(height) as f64 / 2.0),
    };
    let mut best: Option<(f64, f64, bool)> = None;
    // A subset of images keeps the search cheap for large data sets.
    let step = (obs.len() / 8).max(1);
    let sample: Vec<&Observation> = obs.iter().step_by(step).collect();
    for k in 0..24 {
        let gamma = r * 0.1 * (30.0f64).powf(k as f64 / 23.0);
        let model = Model::mei(centre, xi, gamma, fixed);
        for mirrored in [false, true] {
            let errs: Vec<f64> = sample
                .iter()
                .map(|o| {
                    let o = if mirrored { o.mirrored() } else { (*o).clone() };
                    initial_pose(&model, &model.full, &o, 8).map(|x| x.1).unwrap_or(1e6)
                })
                .collect();
            let score = median(errs);
            if best.is_none_or(|b| score < b.0) {
                best = Some((score, gamma, mirrored));
            }
        }
    }
    let (_, gamma, mirrored) = best?;
    Some((Model::mei(centre, xi, gamma, fixed), mirrored))
}

/// Joint refinement with outlier rejection. Returns the model, poses (per `obs` index, `None` =
/// rejected) and rejection reasons.
#[derive(Debug, Clone)]
struct Fit {
    model: Model,
    poses: Vec<Option<[f64; 6]>>,
    reasons: Vec<Option<String>>,
    /// Each image's residual weight in the final fit (1 where the images were not reweighted).
    weights: Vec<f64>,
}

fn joint_fit(mut model: Model, obs: &[Observation], mut poses: Vec<Option<[f64; 6]>>, opts: &Options) -> Option<Fit> {
    let mut reasons: Vec<Option<String>> = poses
        .iter()
        .map(|p| if p.is_none() { Some("no pose found for the board".to_string()) } else { None })
        .collect();
    let mut weights: Option<Vec<f64>> = None;
    loop {
        let used: Vec<usize> = (0..obs.len()).filter(|&k| poses[k].is_some() && reasons[k].is_none()).collect();
        if used.is_empty() {
            return None;
        }
        let sub: Vec<Observation> = used.iter().map(|&k| obs[k].clone()).collect();
        let mut x0 = model.free_values();
        for &k in &used {
            x0.extend_from_slice(&poses[k]?);
        }
        let mut problem = Joint::new(&model, &sub);
        if let Some(w) = &weights {
            problem.weights = used.iter().map(|&k| w[k]).collect();
        }
        let lm_opts =
            lm::Options { max_iterations: opts.max_iterations, huber: Some(opts.huber_px), ..Default::default() };
        let report = lm::minimize(&problem, &x0, &lm_opts);
        let ni = model.free.len();
        model.full = model.with_free(&report.params[..ni]);
        for (s, &k) in used.iter().enumerate() {
            poses[k] = Some(report.params[ni + 6 * s..ni + 6 * s + 6].try_into().ok()?);
        }
        // Outlier images after the fit.
        let rms_of: Vec<f64> = used
            .iter()
            .map(|&k| poses[k].map_or(f64::INFINITY, |p| image_rms(&model, &model.full, &p, &obs[k])))
            .collect();
        let med = median(rms_of.clone());
        let limit = (opts.outlier_factor * med).max(opts.outlier_floor_px);
        let worst = rms_of.iter().enumerate().max_by(|a, b| a.1.total_cmp(b.1)).map(|(s, r)| (used[s], *r));
        match worst {
            Some((k, r)) if r > limit && used.len() > 3 => {
                reasons[k] = Some(format!(
                    "outlier after fitting: RMS {r:.3} px per coordinate > {limit:.3} px ({} × median {med:.3} px)",
                    opts.outlier_factor
                ));
            }
            _ if weights.is_none() && opts.reweight_images => {
                // Images differ in noise (tiny, blurred boards near the rim vs large sharp ones):
                // one refit with each image weighted by the inverse of its relative RMS.
                let mut w = vec![1.0; obs.len()];
                for (s, &k) in used.iter().enumerate() {
                    w[k] = (med / rms_of[s].max(1e-9)).clamp(0.3, 3.0);
                }
                weights = Some(w);
            }
            _ => {
                let weights = weights.unwrap_or_else(|| vec![1.0; obs.len()]);
                return Some(Fit { model, poses, reasons, weights });
            }
        }
    }
}

fn image_rms(model: &Model, full: &[f64], pose: &[f64; 6], obs: &Observation) -> f64 {
    let mut r = vec![0.0; 2 * obs.pixels.len()];
    image_residuals(model, full, pose, obs, &mut r);
    rms(&r)
}

/// Polynomial model initialised from a fitted Mei model: the Mei rays at the observed corners
/// give a0, a2, a3, … by linear least squares (affine c = fy/fx, d = e = 0).
fn ocam_from_mei(mei: &Model, obs: &[Observation], degree: usize, width: u32, height: u32) -> Option<Model> {
    let f = &mei.full;
    let (cx, cy, aspect) = (f[3], f[4], f[2] / f[1]);
    let rho_scale = width.min(height) as f64 / 2.0;
    let n = degree; // a0 and a2..a_degree
    let mut rows = Vec::new();
    let mut rhs = Vec::new();
    let mut rho_max: f64 = 0.0;
    for o in obs {
        for px in &o.pixels {
            let Some(d) = mei_unproject(f, &Vector2::new(px[0], px[1])) else { continue };
            let (u, v) = (px[0] - cx, (px[1] - cy) / aspect);
            let rho = u.hypot(v);
            let lateral = d.x.hypot(d.y);
            if rho < 1.0 || lateral < 1e-9 {
                continue;
            }
            rho_max = rho_max.max(rho);
            let mut row = vec![1.0];
            for k in 2..=degree {
                row.push((rho / rho_scale).powi(k as i32));
            }
            rows.push(row);
            rhs.push(d.z * rho / lateral);
        }
    }
    if rows.len() < n + 2 {
        return None;
    }
    let a = DMatrix::from_fn(rows.len(), n, |i, j| rows[i][j]);
    let b = nalgebra::DVector::from_vec(rhs);
    let coef = a.svd(true, true).solve(&b, 1e-12).ok()?;
    let mut full = vec![cx, cy, aspect, 0.0, 0.0];
    full.extend(coef.iter());
    let mut names: Vec<String> = ["cx_px", "cy_px", "c", "d", "e", "a0"].iter().map(|s| s.to_string()).collect();
    for k in 2..=degree {
        names.push(format!("a{k}"));
    }
    Some(Model {
        kind: ModelKind::Ocam,
        // e stays 0: a rotation of the image about the centre (d = −e) is a rotation of all rays
        // about the axis, which the board poses absorb — a gauge, not a parameter.
        free: (0..full.len()).filter(|&i| i != 4).collect(),
        full,
        names,
        rho_scale,
        rho_max: (width as f64).hypot(height as f64).max(2.0 * rho_max),
        non_central: None,
    })
}

/// An ordinary-camera model (`kind`: pinhole, pinhole-radtan or fisheye) initialised from a
/// fitted Mei model: its principal point and aspect, and the focal length and distortion by
/// linear least squares from the Mei rays at the observed corners (the image radius is linear
/// in f, f·k1, f·k2, …: u − cx = f·a·(1 + k1·r² + …) for the pinhole, ρ = f·θ·(1 + k1·θ² + …)
/// for the fisheye); tangential terms start at 0.
fn ordinary_from_mei(mei: &Model, obs: &[Observation], kind: ModelKind) -> Option<Model> {
    let f = &mei.full;
    let (cx, cy, aspect) = (f[3], f[4], f[2] / f[1]);
    let n = match kind {
        ModelKind::Pinhole => 4,
        ModelKind::PinholeRadtan => 3,
        _ => 5,
    };
    let (mut rows, mut rhs) = (Vec::new(), Vec::new());
    for px in obs.iter().flat_map(|o| &o.pixels) {
        let Some(d) = mei_unproject(f, &Vector2::new(px[0], px[1])) else { continue };
        let (u, v) = (px[0] - cx, (px[1] - cy) / aspect);
        let lateral = d.x.hypot(d.y);
        if kind == ModelKind::Fisheye {
            let t = lateral.atan2(-d.z);
            if lateral < 1e-9 {
                continue;
            }
            rows.push((0..n).map(|k| t.powi(2 * k as i32 + 1)).collect::<Vec<f64>>());
            rhs.push(u.hypot(v));
        } else {
            if -d.z < 0.05 {
                continue;
            }
            let (a, b) = (d.x / -d.z, d.y / -d.z);
            let r2 = a * a + b * b;
            for (x, target) in [(a, u), (b, v)] {
                rows.push((0..n).map(|k| x * r2.powi(k as i32)).collect());
                rhs.push(target);
            }
        }
    }
    if rows.len() < n + 4 {
        return None;
    }
    let a = DMatrix::from_fn(rows.len(), n, |i, j| rows[i][j]);
    let c = a.svd(true, true).solve(&nalgebra::DVector::from_vec(rhs), 1e-14).ok()?;
    let focal = c[0];
    if !(focal > 0.0) {
        return None;
    }
    let k: Vec<f64> = (1..n).map(|i| c[i] / focal).collect();
    let at = |i: usize| k.get(i).copied().unwrap_or(0.0);
    let (full, names, free): (Vec<f64>, &[&str], Vec<usize>) = match kind {
        ModelKind::Fisheye => (
            vec![focal, focal * aspect, cx, cy, at(0), at(1), at(2), at(3)],
            &["fx_px", "fy_px", "cx_px", "cy_px", "k1", "k2", "k3", "k4"],
            (0..8).collect(),
        ),
        _ => (
            vec![focal, focal * aspect, cx, cy, at(0), at(1), 0.0, 0.0, at(2)],
            &["fx_px", "fy_px", "cx_px", "cy_px", "k1", "k2", "p1", "p2", "k3"],
            // Kalibr's radtan has no k3: it stays 0.
            if kind == ModelKind::PinholeRadtan { (0..8).collect() } else { (0..9).collect() },
        ),
    };
    Some(Model {
        kind,
        full,
        free,
        names: names.iter().map(|s| s.to_string()).collect(),
        rho_scale: 1.0,
        rho_max: 0.0,
        non_central: None,
    })
}

/// Calibrates the receiver from the corners of board images of size `width × height` px.
pub fn calibrate(width: u32, height: u32, obs: &[Observation], opts: &Options) -> Result<Calibration, String> {
    let mut images: Vec<ImageReport> = obs
        .iter()
        .map(|o| ImageReport {
            name: o.name.clone(),
            corners: o.pixels.len(),
            rms_px: None,
            used: false,
            reason: None,
            pose: None,
        })
        .collect();
    let mut usable: Vec<usize> = Vec::new();
    for (k, o) in obs.iter().enumerate() {
        if o.pixels.len() != o.board_mm.len() {
            images[k].reason = Some("corner and board point counts differ".into());
        } else if o.pixels.len() < opts.min_corners {
            images[k].reason = Some(format!("too few corners ({} < {})", o.pixels.len(), opts.min_corners));
        } else {
            usable.push(k);
        }
    }
    if usable.len() < 2 {
        return Err(format!("need at least 2 usable board images, have {}", usable.len()));
    }
    if let Some(a) = opts.annulus
        && !(a.iter().all(|v| v.is_finite()) && a[2] >= 0.0 && a[2] < a[3])
    {
        return Err(format!("annulus {a:?}: expected finite centre and 0 ≤ inner radius < outer radius (px)"));
    }
    if opts.non_central && opts.model != ModelKind::Hyperbolic {
        return Err(format!("the non-central fit is for the hyperbolic model, not {:?}", opts.model));
    }
    let (xi, fixed) = match opts.model {
        ModelKind::Hyperbolic => {
            let (a, b2) = (opts.mirror.a_mm, opts.mirror.b_mm * opts.mirror.b_mm);
            let c = (a * a + b2).sqrt();
            (2.0 * a * c / (a * a + c * c), true)
        }
        _ => (1.0, false),
    };
    let base: Vec<Observation> = usable.iter().map(|&k| obs[k].clone()).collect();
    let (model, mirrored) = initialise_mei(width, height, opts.annulus, xi, fixed, &base)
        .ok_or("initialisation failed: no pose found for any board")?;
    let sub: Vec<Observation> = if mirrored { base.iter().map(|o| o.mirrored()).collect() } else { base };
    let poses: Vec<Option<[f64; 6]>> =
        sub.iter().map(|o| initial_pose(&model, &model.full, o, 20).map(|x| x.0)).collect();
    let mut fit = joint_fit(model, &sub, poses, opts).ok_or("the joint fit found no usable board")?;
    // The Mei fit the polynomial starts from: the reference of the model check.
    let mut mei_start = None;
    if opts.model.is_ordinary() {
        mei_start = Some(fit.clone());
        let used: Vec<Observation> =
            (0..sub.len()).filter(|&k| fit.reasons[k].is_none()).map(|k| sub[k].clone()).collect();
        let ordinary = ordinary_from_mei(&fit.model, &used, opts.model)
            .ok_or("pinhole/fisheye initialisation failed (too few corners in front of the camera)")?;
        let poses = fit.poses.iter().zip(&fit.reasons).map(|(p, r)| if r.is_none() { *p } else { None }).collect();
        let reasons = fit.reasons.clone();
        fit = joint_fit(ordinary, &sub, poses, opts).ok_or("the pinhole/fisheye fit found no usable board")?;
        for (k, r) in reasons.into_iter().enumerate() {
            if r.is_some() {
                fit.reasons[k] = r;
            }
        }
    }
    if opts.model == ModelKind::Ocam {
        mei_start = Some(fit.clone());
        let used: Vec<Observation> =
            (0..sub.len()).filter(|&k| fit.reasons[k].is_none()).map(|k| sub[k].clone()).collect();
        let ocam = ocam_from_mei(&fit.model, &used, opts.ocam_degree, width, height)
            .ok_or("polynomial initialisation failed (too few corners)")?;
        let poses = fit.poses.iter().zip(&fit.reasons).map(|(p, r)| if r.is_none() { *p } else { None }).collect();
        let reasons = fit.reasons.clone();
        fit = joint_fit(ocam, &sub, poses, opts).ok_or("the polynomial fit found no usable board")?;
        for (k, r) in reasons.into_iter().enumerate() {
            if r.is_some() {
                fit.reasons[k] = r;
            }
        }
    }
    // The central hyperbolic model's viewpoint is the origin of its fit; the camera's world frame
    // (HyperbolicCamera) has it at the mirror's upper focus F = (0, 0, 2c).
    let focus = Vector3::new(0.0, 0.0, 2.0 * opts.mirror.a_mm.hypot(opts.mirror.b_mm));
    if opts.model == ModelKind::Hyperbolic && opts.non_central {
        let nc = Model::non_central(&fit.model, &opts.mirror);
        let poses = fit
            .poses
            .iter()
            .zip(&fit.reasons)
            .map(|(p, r)| {
                let p = (*p).filter(|_| r.is_none())?;
                Some([p[0], p[1], p[2], p[3] + focus.x, p[4] + focus.y, p[5] + focus.z])
            })
            .collect();
        let reasons = fit.reasons.clone();
        fit = joint_fit(nc, &sub, poses, opts).ok_or("the non-central fit found no usable board")?;
        for (k, r) in reasons.into_iter().enumerate() {
            if r.is_some() {
                fit.reasons[k] = r;
            }
        }
    }
    if opts.model == ModelKind::Hyperbolic && !opts.non_central {
        mei_start = Some(fit.clone());
    }
    let pose_shift = if opts.model == ModelKind::Hyperbolic && !opts.non_central { focus } else { Vector3::zeros() };
    // Per-image report.
    let mut all_res = Vec::new();
    for (s, &k) in usable.iter().enumerate() {
        if let Some(p) = fit.poses[s] {
            // A refused image's pose froze when it was refused: posed again under the final
            // intrinsics, its RMS says how far it is from them, not from an earlier model.
            let p = match &fit.reasons[s] {
                Some(_) => initial_pose(&fit.model, &fit.model.full, &sub[s], 20).map_or(p, |(q, _)| q),
                None => p,
            };
            let mut r = vec![0.0; 2 * sub[s].pixels.len()];
            image_residuals(&fit.model, &fit.model.full, &p, &sub[s], &mut r);
            images[k].rms_px = Some(rms(&r));
            images[k].pose = Some(nalgebra::Translation3::from(pose_shift) * params_to_pose(&p));
            if fit.reasons[s].is_none() {
                images[k].used = true;
                all_res.extend(r);
            }
        }
        images[k].reason = fit.reasons[s].clone();
    }
    let std_free = {
        let kept: Vec<usize> = (0..sub.len()).filter(|&k| fit.reasons[k].is_none() && fit.poses[k].is_some()).collect();
        let used: Vec<Observation> = kept.iter().map(|&k| sub[k].clone()).collect();
        let weights: Vec<f64> = kept.iter().map(|&k| fit.weights[k]).collect();
        let mut x = fit.model.free_values();
        for k in (0..sub.len()).filter(|&k| fit.reasons[k].is_none()) {
            x.extend_from_slice(&fit.poses[k].unwrap_or_default());
        }
        intrinsic_std_devs(&fit.model, &used, &weights, &x, opts.huber_px)
    };
    let (names, params, std_devs, mut spec) = describe(&fit.model, &std_free, width, height, opts);
    // Corners that do not constrain a parameter (all at one pixel, one board seen edge-on)
    // leave it, or its uncertainty, undefined: that is no calibration.
    if let Some(((n, v), sd)) =
        names.iter().zip(&params).zip(&std_devs).find(|((_, v), sd)| !(v.is_finite() && sd.is_finite()))
    {
        return Err(format!("the corners do not determine the model: {n} = {v} ± {sd}"));
    }
    let used: Vec<usize> = (0..sub.len()).filter(|&k| fit.reasons[k].is_none() && fit.poses[k].is_some()).collect();
    // Without an annulus' inner circle the mirror's blind centre may not refuse an observed corner.
    if let CameraSpec::Hyperbolic(p) = &mut spec
        && opts.annulus.is_none_or(|a| a[2] <= 0.0)
    {
        let innermost = used
            .iter()
            .flat_map(|&k| &sub[k].pixels)
            .filter_map(|px| mirror_radius_mm(p, &Vector2::new(px[0], px[1])))
            .fold(f64::INFINITY, f64::min);
        if innermost.is_finite() {
            p.inner_radius_mm = p.inner_radius_mm.min(BLIND_CENTRE_MARGIN * innermost);
        }
    }
    let model_check = match mei_start {
        Some(start) if opts.compare_models => {
            validate::compare_with_mei(&start, &fit, &sub, &used, &spec, width, height, opts)
        }
        _ => None,
    };
    Ok(Calibration {
        spec,
        rms_px: rms(&all_res),
        images,
        param_names: names,
        params,
        std_devs,
        mirrored_labels: mirrored,
        model_check,
    })
}

/// Without a known blind centre, the hyperbolic model's inner mirror radius is at most this
/// fraction of the innermost observed corner's.
const BLIND_CENTRE_MARGIN: f64 = 0.9;

/// Standard deviations of the free intrinsics: σ²·(JᵀWJ)⁻¹ with σ² = Σw·r²/(m − n), inverted
/// after Jacobi scaling (the parameters differ by many orders of magnitude). NaN if singular.
/// The residuals and the Jacobian carry the images' weights of the fit (`image_weights`, one per
/// observation): an image the fit found noisier counts for as little here as it did there.
fn intrinsic_std_devs(model: &Model, obs: &[Observation], image_weights: &[f64], x: &[f64], huber: f64) -> Vec<f64> {
    use lm::Problem as _;
    let mut problem = Joint::new(model, obs);
    problem.weights = image_weights.to_vec();
    let (m, n) = (problem.num_residuals(), problem.num_params());
    let ni = model.free.len();
    if x.len() != n || m <= n {
        return vec![f64::NAN; ni];
    }
    let mut r = vec![0.0; m];
    problem.residuals(x, &mut r);
    let mut jac = DMatrix::<f64>::zeros(m, n);
    problem.jacobian(x, &mut jac);
    let w: Vec<f64> = r.iter().map(|ri| if ri.abs() > huber { huber / ri.abs() } else { 1.0 }).collect();
    let sigma2 = r.iter().zip(&w).map(|(r, w)| w * r * r).sum::<f64>() / (m - n) as f64;
    let mut jtj = DMatrix::<f64>::zeros(n, n);
    for i in 0..m {
        let row = jac.row(i);
        for a in 0..n {
            let ja = row[a] * w[i];
            if ja != 0.0 {
                for b in 0..n {
                    jtj[(a, b)] += ja * row[b];
                }
            }
        }
    }
    let d: Vec<f64> = (0..n).map(|i| jtj[(i, i)].max(1e-300).sqrt()).collect();
    let scaled = DMatrix::from_fn(n, n, |a, b| jtj[(a, b)] / (d[a] * d[b]));
    match scaled.cholesky() {
        Some(ch) => {
            let inv = ch.inverse();
            (0..ni).map(|i| (sigma2 * inv[(i, i)]).max(0.0).sqrt() / d[i]).collect()
        }
        None => vec![f64::NAN; ni],
    }
}

/// f = γ·(a² + c²)/b²: the pinhole focal length of the hyperbolic camera whose Mei model has the
/// generalised focal length γ.
fn hyperbolic_focal_factor(mirror: &HyperbolicParams) -> f64 {
    let (a2, b2) = (mirror.a_mm * mirror.a_mm, mirror.b_mm * mirror.b_mm);
    (a2 + (a2 + b2)) / b2
}

/// Mirror radius (mm) seen at a pixel of the hyperbolic camera `p` (rim and blind centre not
/// checked).
fn mirror_radius_mm(p: &HyperbolicParams, px: &Vector2<f64>) -> Option<f64> {
    let open = HyperbolicParams { inner_radius_mm: 0.0, ..p.clone() };
    let m = HyperbolicCamera::new(open).ok()?.mirror_point(px)?;
    Some(m.x.hypot(m.y))
}

/// The blind-centre radius on the mirror (mm) of the annulus' inner circle [cx, cy, inner, _] px:
/// the mean mirror radius seen on it (12 pixels around it; a camera off the focus images the
/// circle slightly off the annulus' centre); `None` without an inner circle.
fn blind_centre_mm(p: &HyperbolicParams, annulus: [f64; 4]) -> Option<f64> {
    if annulus[2] <= 0.0 {
        return None;
    }
    let radii: Vec<f64> = (0..12)
        .filter_map(|k| {
            let a = k as f64 * std::f64::consts::TAU / 12.0;
            mirror_radius_mm(p, &Vector2::new(annulus[0] + annulus[2] * a.cos(), annulus[1] + annulus[2] * a.sin()))
        })
        .collect();
    let r = radii.iter().sum::<f64>() / radii.len() as f64;
    (r.is_finite() && r < p.rim_radius_mm).then_some(r)
}

/// Names, values, standard deviations of the fitted parameters and the camera spec.
fn describe(
    model: &Model,
    std_free: &[f64],
    width: u32,
    height: u32,
    opts: &Options,
) -> (Vec<String>, Vec<f64>, Vec<f64>, CameraSpec) {
    let f = &model.full;
    // The model holds inside the mirror annulus (radii about the fitted principal point).
    let [inner_radius_px, outer_radius_px] = opts.annulus.map_or([0.0, 0.0], |a| [a[2], a[3]]);
    let mut std_full = vec![0.0; f.len()];
    for (k, &i) in model.free.iter().enumerate() {
        std_full[i] = std_free[k];
    }
    match model.kind {
        ModelKind::Mei => {
            let p = MeiParams { inner_radius_px, outer_radius_px, ..MeiParams::from_vector(f, width, height) };
            (model.names.clone(), f.clone(), std_full, CameraSpec::Mei(p))
        }
        ModelKind::Hyperbolic => {
            let m = &opts.mirror;
            let (mut p, names, values, stds) = if model.non_central.is_some() {
                let p = HyperbolicParams {
                    fx_px: f[0],
                    fy_px: f[1],
                    cx_px: f[2],
                    cy_px: f[3],
                    width,
                    height,
                    camera_offset_mm: [f[4], f[5], f[6]],
                    camera_tilt_deg: [f[7], f[8]],
                    ..m.clone()
                };
                (p, model.names.clone(), f.clone(), std_full)
            } else {
                let k = hyperbolic_focal_factor(m);
                let p = HyperbolicParams {
                    fx_px: f[1] * k,
                    fy_px: f[2] * k,
                    cx_px: f[3],
                    cy_px: f[4],
                    width,
                    height,
                    camera_offset_mm: [0.0; 3],
                    camera_tilt_deg: [0.0; 2],
                    ..m.clone()
                };
                let names = vec!["fx_px".into(), "fy_px".into(), "cx_px".into(), "cy_px".into()];
                let values = vec![p.fx_px, p.fy_px, p.cx_px, p.cy_px];
                let stds = vec![std_full[1] * k, std_full[2] * k, std_full[3], std_full[4]];
                (p, names, values, stds)
            };
            if let Some(inner) = opts.annulus.and_then(|a| blind_centre_mm(&p, a)) {
                p.inner_radius_mm = inner;
            }
            (names, values, stds, CameraSpec::Hyperbolic(p))
        }
        ModelKind::Ocam => {
            let v = model.ocam_vector(f);
            let mut p = OcamParams {
                poly: v[5..].to_vec(),
                inv_poly: Vec::new(),
                cx_px: v[0],
                cy_px: v[1],
                c: v[2],
                d: v[3],
                e: v[4],
                width,
                height,
                inner_radius_px,
                outer_radius_px,
                viewpoint_mm: [0.0; 3],
            };
            p.fit_inverse_poly(omni_model::ocam::INVERSE_TOLERANCE_PX, omni_model::ocam::INVERSE_MAX_DEGREE);
            let mut values = v[..6].to_vec();
            let mut stds = std_full[..6].to_vec();
            for k in 2..=opts.ocam_degree {
                let s = model.rho_scale.powi(k as i32);
                values.push(f[4 + k] / s);
                stds.push(std_full[4 + k] / s);
            }
            (model.names.clone(), values, stds, CameraSpec::Ocam(p))
        }
        ModelKind::Pinhole | ModelKind::PinholeRadtan => {
            let spec = CameraSpec::Pinhole(PinholeParams::from_vector(f, width, height));
            let keep: Vec<usize> = if model.kind == ModelKind::Pinhole { (0..9).collect() } else { (0..8).collect() };
            let pick = |v: &[f64]| keep.iter().map(|&i| v[i]).collect::<Vec<f64>>();
            (keep.iter().map(|&i| model.names[i].clone()).collect(), pick(f), pick(&std_full), spec)
        }
        ModelKind::Fisheye => {
            let spec = CameraSpec::Fisheye(FisheyeParams::from_vector(f, width, height));
            (model.names.clone(), f.clone(), std_full, spec)
        }
    }
}

#[cfg(test)]
mod ordinary_tests;
#[cfg(test)]
mod tests;
