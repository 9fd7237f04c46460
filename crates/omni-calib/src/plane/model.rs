//! The physical transmitter fitted to all frames at once (SENSOR.md, "Beyond the paper").
//!
//! Each observation is a set of 3D points lit by laser j in a frame (mirror angle α, facet k);
//! the residual of a point is its signed distance (mm) to the model's light plane
//! [`Transmitter::light_plane`]. Fitted parameters:
//!
//! * polygon axis direction: 2 tilts (rad) of the initial direction towards two perpendiculars;
//! * polygon axis point: 2 offsets (mm) perpendicular to the initial axis;
//! * encoder zero ε (rad);
//! * per observed facet: pitch (rad), tilt (rad), radius error (mm), each block with zero mean;
//! * per observed laser: its fan plane (normal tilt towards the axis and turn about it in rad,
//!   offset in mm).
//!
//! Gauge freedoms, fixed explicitly. Exact ones (they change no light plane at all):
//! * a common pitch of all facets is the same as the encoder zero: pitches are fitted with
//!   **zero mean over the observed facets**, so ε is the encoder zero of the average facet;
//! * turning `zero_dir` about the axis is again the encoder zero: `zero_dir` stays the initial
//!   one projected perpendicular to the fitted axis;
//! * the axis point may slide along the axis: it moves only perpendicular to the initial axis;
//! * a laser's apex, central direction and fan axis matter only through its fan plane: the apex
//!   is projected onto the fitted plane and the direction kept as close to the initial one as the
//!   plane allows (they still decide which points count as lit).
//!
//! Near-gauges (a rig cannot tell them apart: fitted freely their standard deviations reach
//! degrees and millimetres, while the light planes stay the same to a few thousandths of a
//! degree), fixed so that the fitted numbers mean something:
//! * turning the first observed laser's fan about the polygon axis ≈ changing the encoder zero
//!   (the reflected plane turns by −δ or by +2ε): that laser's turn stays at its initial value,
//!   so ε is measured relative to the laser's mounting;
//! * a common facet tilt ≈ tilting the fan plane towards the axis, and a common radius error ≈
//!   shifting the fan plane and the axis: tilts and radius errors have **zero mean** over the
//!   observed facets.
//!
//! Facets and lasers without observations keep their initial values (listed in the report).

use nalgebra::{DMatrix, Point3, Vector3};
use omni_geom::Plane;
use omni_geom::fit::orthonormal_basis;
use omni_geom::lm::{self, Problem};
use omni_model::{FacetError, LaserParams, Transmitter, TransmitterParams};
use serde::Serialize;

/// Points of one (frame, laser) for the model fit.
#[derive(Debug, Clone)]
pub struct Observation {
    /// Mirror angle within the facet (radians).
    pub alpha_rad: f64,
    /// Facet facing laser 0.
    pub facet: u32,
    pub laser: usize,
    /// World points (mm).
    pub points: Vec<Point3<f64>>,
}

/// Settings of the model fit.
#[derive(Debug, Clone, Copy)]
pub struct ModelFitOptions {
    /// Points farther than max(`outlier_sigmas`·σ_MAD, `outlier_floor_mm`) from the first fit's
    /// planes are dropped before the final, Huber-weighted fit.
    pub outlier_sigmas: f64,
    pub outlier_floor_mm: f64,
    pub max_iterations: usize,
}

impl Default for ModelFitOptions {
    fn default() -> Self {
        ModelFitOptions { outlier_sigmas: 4.0, outlier_floor_mm: 0.2, max_iterations: 100 }
    }
}

/// One fitted scalar with its standard deviation.
#[derive(Debug, Clone, Serialize)]
pub struct Estimate {
    pub name: String,
    pub value: f64,
    /// The whole σ: the fit's own, and the boards' pose errors' where the poses came from
    /// corners. `None` when the fit's covariance was singular.
    pub std: Option<f64>,
    pub unit: &'static str,
    /// The fit's own σ (the LM covariance: stripe points' errors independent), where the
    /// boards' share was added.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub std_fit: Option<f64>,
    /// The boards' pose errors' share of the σ.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub std_board_poses: Option<f64>,
}

/// Result of the physical model fit.
#[derive(Debug, Clone)]
pub struct ModelFit {
    pub params: TransmitterParams,
    /// RMS point-to-plane distance of the points kept (mm).
    pub rms_mm: f64,
    pub points_used: usize,
    pub outliers: usize,
    pub iterations: usize,
    pub converged: bool,
    pub estimates: Vec<Estimate>,
    /// What was kept at its initial value, and why.
    pub fixed: Vec<String>,
    /// Per observation: RMS of its kept points to the model plane (mm).
    pub observation_rms_mm: Vec<f64>,
}

/// Basis of a laser's fan plane perturbation: `u` tilts the fan normal towards the polygon axis,
/// `v` turns it about the axis (fixed for the first observed laser: a gauge with the encoder zero).
#[derive(Debug, Clone)]
struct LaserBasis {
    index: usize,
    n0: Vector3<f64>,
    u: Vector3<f64>,
    v: Vector3<f64>,
    offset0: f64,
    init: LaserParams,
    /// Whether the turn about the axis is a free parameter.
    turns: bool,
    /// Index of this laser's first parameter.
    start: usize,
}

impl LaserBasis {
    fn len(&self) -> usize {
        if self.turns { 3 } else { 2 }
    }
}

/// Maps the parameter vector to [`TransmitterParams`]. Layout: axis tilts (2), axis point (2),
/// encoder zero (1), then for the observed facets pitches, tilts and radius errors (each with
/// zero mean: n − 1 free values, the last is minus their sum), then the lasers.
#[derive(Debug, Clone)]
struct Layout {
    base: TransmitterParams,
    a0: Vector3<f64>,
    au: Vector3<f64>,
    av: Vector3<f64>,
    c0: Vector3<f64>,
    zero_ref: Vector3<f64>,
    facets: Vec<u32>,
    lasers: Vec<LaserBasis>,
}

const I_AXIS: usize = 0;
const I_POINT: usize = 2;
const I_ENC: usize = 4;
const I_FACETS: usize = 5;

/// Mean of the per-facet values of the observed facets.
fn facet_mean(errs: &[FacetError], facets: &[u32], get: impl Fn(&FacetError) -> f64) -> f64 {
    facets.iter().map(|&k| get(&errs[k as usize])).sum::<f64>() / facets.len().max(1) as f64
}

impl Layout {
    fn new(base: &TransmitterParams, facets: Vec<u32>, lasers: &[usize]) -> Self {
        let a0 = Vector3::from(base.polygon.axis_dir).normalize();
        let (au, av) = orthonormal_basis(&a0);
        let n_free = facets.len().saturating_sub(1);
        let mut start = I_FACETS + 3 * n_free;
        let lasers = lasers
            .iter()
            .enumerate()
            .map(|(i, &j)| {
                let l = &base.lasers[j];
                let n0 = Vector3::from(l.direction).cross(&Vector3::from(l.fan_axis)).normalize();
                let towards_axis = a0 - n0 * n0.dot(&a0);
                let (u, v) = if towards_axis.norm() > 1e-6 {
                    let u = towards_axis.normalize();
                    (u, n0.cross(&u))
                } else {
                    orthonormal_basis(&n0)
                };
                let basis = LaserBasis {
                    index: j,
                    n0,
                    u,
                    v,
                    offset0: n0.dot(&Vector3::from(l.source_mm)),
                    init: l.clone(),
                    turns: i > 0,
                    start,
                };
                start += basis.len();
                basis
            })
            .collect();
        let mut base = base.clone();
        let n = base.polygon.facets as usize;
        if base.polygon.facet_errors.is_empty() {
            base.polygon.facet_errors = vec![FacetError::default(); n];
        }
        // The observed facets' mean pitch moves into the encoder zero (initial_vector), so the
        // unobserved facets' pitches shift by the same amount to keep their planes unchanged.
        let mean_pitch = facet_mean(&base.polygon.facet_errors, &facets, |e| e.pitch_deg);
        for (k, e) in base.polygon.facet_errors.iter_mut().enumerate() {
            if !facets.contains(&(k as u32)) {
                e.pitch_deg -= mean_pitch;
            }
        }
        Layout {
            a0,
            au,
            av,
            c0: Vector3::from(base.polygon.axis_point_mm),
            zero_ref: Vector3::from(base.polygon.zero_dir),
            base,
            facets,
            lasers,
        }
    }

    fn n_free(&self) -> usize {
        self.facets.len().saturating_sub(1)
    }
    fn i_tilt(&self) -> usize {
        I_FACETS + self.n_free()
    }
    fn i_radius(&self) -> usize {
        self.i_tilt() + self.n_free()
    }
    fn len(&self) -> usize {
        self.lasers.last().map_or(I_FACETS + 3 * self.n_free(), |l| l.start + l.len())
    }

    /// The parameter vector of the initial model. The observed facets' pitches, tilts and radius
    /// errors are moved to zero mean: the mean pitch goes into the encoder zero (same planes);
    /// mean tilt and radius are dropped (the fit moves the axis and fan planes to make up for them).
    fn initial_vector(&self) -> Vec<f64> {
        let mut p = vec![0.0; self.len()];
        let errs = &self.base.polygon.facet_errors;
        let mean_pitch = facet_mean(errs, &self.facets, |e| e.pitch_deg).to_radians();
        let mean_tilt = facet_mean(errs, &self.facets, |e| e.tilt_deg).to_radians();
        let mean_radius = facet_mean(errs, &self.facets, |e| e.radius_mm);
        p[I_ENC] = self.base.polygon.encoder_zero_deg.to_radians() + mean_pitch;
        for (i, &k) in self.facets[..self.n_free()].iter().enumerate() {
            let e = &errs[k as usize];
            p[I_FACETS + i] = e.pitch_deg.to_radians() - mean_pitch;
            p[self.i_tilt() + i] = e.tilt_deg.to_radians() - mean_tilt;
            p[self.i_radius() + i] = e.radius_mm - mean_radius;
        }
        p
    }

    /// Value `i` (in observed-facet order) of a zero-mean block starting at `start`.
    fn zero_mean(&self, p: &[f64], start: usize, i: usize) -> f64 {
        let n = self.n_free();
        if i < n { p[start + i] } else { -p[start..start + n].iter().sum::<f64>() }
    }

    fn params(&self, p: &[f64]) -> TransmitterParams {
        let mut t = self.base.clone();
        let axis = (self.a0 + self.au * p[I_AXIS] + self.av * p[I_AXIS + 1]).normalize();
        let point = self.c0 + self.au * p[I_POINT] + self.av * p[I_POINT + 1];
        let zero = (self.zero_ref - axis * axis.dot(&self.zero_ref)).normalize();
        t.polygon.axis_dir = axis.into();
        t.polygon.axis_point_mm = point.into();
        t.polygon.zero_dir = zero.into();
        t.polygon.encoder_zero_deg = p[I_ENC].to_degrees();
        for (i, &k) in self.facets.iter().enumerate() {
            t.polygon.facet_errors[k as usize] = FacetError {
                tilt_deg: self.zero_mean(p, self.i_tilt(), i).to_degrees(),
                pitch_deg: self.zero_mean(p, I_FACETS, i).to_degrees(),
                radius_mm: self.zero_mean(p, self.i_radius(), i),
            };
        }
        for l in &self.lasers {
            let q = &p[l.start..l.start + l.len()];
            let turn = if l.turns { q[2] } else { 0.0 };
            let n = (l.n0 + l.u * q[0] + l.v * turn).normalize();
            let offset = l.offset0 + q[1];
            let src0 = Vector3::from(l.init.source_mm);
            let src = src0 - n * (n.dot(&src0) - offset);
            let d0 = Vector3::from(l.init.direction);
            let dir = (d0 - n * n.dot(&d0)).normalize();
            t.lasers[l.index] = LaserParams {
                source_mm: src.into(),
                direction: dir.into(),
                fan_axis: n.cross(&dir).into(),
                ..l.init.clone()
            };
        }
        t
    }

    /// (name, unit, stored in radians → reported in degrees) of every parameter, in order.
    fn names(&self) -> Vec<(String, &'static str, bool)> {
        let mut v = vec![
            ("polygon.axis_dir tilt u".to_string(), "deg", true),
            ("polygon.axis_dir tilt v".to_string(), "deg", true),
            ("polygon.axis_point offset u".to_string(), "mm", false),
            ("polygon.axis_point offset v".to_string(), "mm", false),
            ("polygon.encoder_zero_deg".to_string(), "deg", true),
        ];
        let free = &self.facets[..self.n_free()];
        v.extend(free.iter().map(|k| (format!("facet_errors[{k}].pitch_deg"), "deg", true)));
        v.extend(free.iter().map(|k| (format!("facet_errors[{k}].tilt_deg"), "deg", true)));
        v.extend(free.iter().map(|k| (format!("facet_errors[{k}].radius_mm"), "mm", false)));
        for l in &self.lasers {
            v.push((format!("lasers[{}] fan normal tilt towards the axis", l.index), "deg", true));
            v.push((format!("lasers[{}] fan plane offset", l.index), "mm", false));
            if l.turns {
                v.push((format!("lasers[{}] fan normal turn about the axis", l.index), "deg", true));
            }
        }
        v
    }
}

/// Least-squares problem: signed distances of all points to their model light planes.
struct TransmitterProblem<'a> {
    layout: &'a Layout,
    obs: &'a [Observation],
    /// Reference normals that fix each plane's orientation (so residual signs never flip).
    reference: Vec<Vector3<f64>>,
    n_res: usize,
}

impl TransmitterProblem<'_> {
    /// The model light plane of every observation, oriented along the reference normals.
    fn planes(&self, p: &[f64]) -> Vec<Plane> {
        let fallback = Plane::from_point_normal(&Point3::origin(), &Vector3::z());
        let tx = Transmitter::new(self.layout.params(p));
        self.obs
            .iter()
            .zip(&self.reference)
            .map(|(o, r)| {
                let plane = tx
                    .as_ref()
                    .ok()
                    .and_then(|tx| tx.light_plane(o.alpha_rad, o.facet, o.laser))
                    .map(|lp| lp.plane)
                    .unwrap_or(Plane { normal: fallback.normal, offset: f64::NAN });
                if plane.normal.dot(r) < 0.0 { plane.flipped() } else { plane }
            })
            .collect()
    }
}

impl Problem for TransmitterProblem<'_> {
    fn num_params(&self) -> usize {
        self.layout.len()
    }
    fn num_residuals(&self) -> usize {
        self.n_res
    }
    fn residuals(&self, p: &[f64], out: &mut [f64]) {
        let mut i = 0;
        for (o, plane) in self.obs.iter().zip(self.planes(p)) {
            for x in &o.points {
                out[i] = plane.signed_distance(x);
                i += 1;
            }
        }
    }
    /// Exact chain rule through each observation's plane: ∂r/∂p = x·∂n/∂p − ∂d/∂p, with the
    /// plane derivatives by central differences (1e-7 rad or mm; all parameters are O(1)).
    fn jacobian(&self, p: &[f64], jac: &mut DMatrix<f64>) {
        let mut q = p.to_vec();
        for j in 0..p.len() {
            let h = 1e-7;
            q[j] = p[j] + h;
            let plus = self.planes(&q);
            q[j] = p[j] - h;
            let minus = self.planes(&q);
            q[j] = p[j];
            let mut i = 0;
            for (o, (a, b)) in self.obs.iter().zip(plus.iter().zip(&minus)) {
                let dn = (a.normal.into_inner() - b.normal.into_inner()) / (2.0 * h);
                let dd = (a.offset - b.offset) / (2.0 * h);
                for x in &o.points {
                    jac[(i, j)] = dn.dot(&x.coords) - dd;
                    i += 1;
                }
            }
        }
    }
}

/// The facet index (0..n) laser `laser` uses in an observation.
fn used_facet(params: &TransmitterParams, o: &Observation) -> u32 {
    let n = params.polygon.facets;
    (o.facet % n + params.lasers[o.laser].facet_offset % n) % n
}

/// Fits the physical transmitter to all observations, starting from `initial`.
pub fn fit_transmitter(
    initial: &TransmitterParams,
    observations: &[Observation],
    opts: &ModelFitOptions,
) -> Result<ModelFit, String> {
    Transmitter::new(initial.clone()).map_err(|e| format!("initial transmitter: {e}"))?;
    if let Some(o) = observations.iter().find(|o| o.laser >= initial.lasers.len()) {
        return Err(format!("laser {} is not in the transmitter model", o.laser));
    }
    let obs: Vec<Observation> = observations.iter().filter(|o| !o.points.is_empty()).cloned().collect();
    let total: usize = obs.iter().map(|o| o.points.len()).sum();
    let mut facets: Vec<u32> = obs.iter().map(|o| used_facet(initial, o)).collect();
    facets.sort_unstable();
    facets.dedup();
    let mut lasers: Vec<usize> = obs.iter().map(|o| o.laser).collect();
    lasers.sort_unstable();
    lasers.dedup();
    let layout = Layout::new(initial, facets, &lasers);
    if total < layout.len() * 3 || obs.len() < 3 {
        return Err(format!(
            "too few observations for the transmitter model: {} frames with {total} points for {} parameters",
            obs.len(),
            layout.len()
        ));
    }
    let p0 = layout.initial_vector();
    let reference: Vec<Vector3<f64>> = {
        let tx = Transmitter::new(layout.params(&p0))?;
        obs.iter()
            .map(|o| {
                tx.light_plane(o.alpha_rad, o.facet, o.laser)
                    .map(|lp| lp.plane.normal.into_inner())
                    .ok_or_else(|| format!("laser {} runs parallel to its facet at α = {} rad", o.laser, o.alpha_rad))
            })
            .collect::<Result<_, _>>()?
    };
    let lm_opts = lm::Options { max_iterations: opts.max_iterations, ..Default::default() };
    let first = {
        let problem = TransmitterProblem { layout: &layout, obs: &obs, reference: reference.clone(), n_res: total };
        lm::minimize(&problem, &p0, &lm_opts)
    };
    // Drop outliers against the first fit, then refit the rest with a Huber loss.
    let planes = TransmitterProblem { layout: &layout, obs: &obs, reference: reference.clone(), n_res: total }
        .planes(&first.params);
    let dist: Vec<f64> =
        obs.iter().zip(&planes).flat_map(|(o, pl)| o.points.iter().map(|x| pl.signed_distance(x))).collect();
    let sigma = super::observe::robust_sigma(&dist);
    let limit = (opts.outlier_sigmas * sigma).max(opts.outlier_floor_mm);
    let mut kept_obs = obs.clone();
    let mut k = 0;
    for o in &mut kept_obs {
        let mut pts = Vec::with_capacity(o.points.len());
        for x in &o.points {
            if dist[k].abs() <= limit {
                pts.push(*x);
            }
            k += 1;
        }
        o.points = pts;
    }
    let kept: usize = kept_obs.iter().map(|o| o.points.len()).sum();
    let problem = TransmitterProblem { layout: &layout, obs: &kept_obs, reference, n_res: kept };
    let huber = lm::Options { huber: Some((2.0 * sigma).max(1e-3)), ..lm_opts };
    let report = lm::minimize(&problem, &first.params, &huber);
    if !report.params.iter().all(|x| x.is_finite()) {
        return Err("the transmitter fit diverged (non-finite parameters)".into());
    }
    let params = layout.params(&report.params);
    Transmitter::new(params.clone()).map_err(|e| format!("fitted transmitter is invalid: {e}"))?;
    let planes = problem.planes(&report.params);
    let observation_rms_mm = kept_obs
        .iter()
        .zip(&planes)
        .map(|(o, pl)| {
            let ss: f64 = o.points.iter().map(|x| pl.signed_distance(x).powi(2)).sum();
            (ss / o.points.len().max(1) as f64).sqrt()
        })
        .collect();
    Ok(ModelFit {
        estimates: estimates(&layout, &report),
        fixed: fixed_parameters(initial, &layout),
        params,
        rms_mm: report.rms,
        points_used: kept,
        outliers: total - kept,
        iterations: first.iterations + report.iterations,
        converged: report.converged,
        observation_rms_mm,
    })
}

/// Named values and standard deviations, in degrees and mm; includes the gauge-determined last
/// pitch (minus the sum of the others) with its propagated deviation.
fn estimates(layout: &Layout, report: &lm::Report) -> Vec<Estimate> {
    let p = &report.params;
    let cov = report.covariance.as_ref();
    let std = |i: usize| cov.map(|c| c[(i, i)].max(0.0).sqrt());
    let mut out: Vec<Estimate> = layout
        .names()
        .into_iter()
        .enumerate()
        .map(|(i, (name, unit, radians))| {
            let scale = if radians { 1f64.to_degrees() } else { 1.0 };
            Estimate {
                name,
                value: p[i] * scale,
                std: std(i).map(|s| s * scale),
                unit,
                std_fit: None,
                std_board_poses: None,
            }
        })
        .collect();
    if let (Some(&last), true) = (layout.facets.last(), layout.facets.len() > 1) {
        let n = layout.n_free();
        let blocks = [
            (I_FACETS, "pitch_deg", "deg", true),
            (layout.i_tilt(), "tilt_deg", "deg", true),
            (layout.i_radius(), "radius_mm", "mm", false),
        ];
        for (start, field, unit, radians) in blocks {
            let scale = if radians { 1f64.to_degrees() } else { 1.0 };
            let var =
                cov.map(|c| (start..start + n).flat_map(|a| (start..start + n).map(move |b| c[(a, b)])).sum::<f64>());
            out.push(Estimate {
                name: format!("facet_errors[{last}].{field} (gauge: minus the sum of the other facets')"),
                value: layout.zero_mean(p, start, layout.facets.len() - 1) * scale,
                std: var.map(|v| v.max(0.0).sqrt() * scale),
                unit,
                std_fit: None,
                std_board_poses: None,
            });
        }
    }
    out
}

fn fixed_parameters(initial: &TransmitterParams, layout: &Layout) -> Vec<String> {
    let mut fixed = vec![];
    for k in 0..initial.polygon.facets {
        if !layout.facets.contains(&k) {
            fixed.push(format!("facet_errors[{k}]: facet not observed, kept at its initial value"));
        }
    }
    for j in 0..initial.lasers.len() {
        if !layout.lasers.iter().any(|l| l.index == j) {
            fixed.push(format!("lasers[{j}]: laser not observed, kept at its initial value"));
        }
    }
    fixed.push("polygon.circumradius_mm: nominal (radius errors are fitted per facet)".into());
    fixed
}
