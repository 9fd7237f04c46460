//! The virtual sensor: scenes and physically based rendering of laser and checkerboard frames
//! with ground truth.
//!
//! `omni-sim` is how omniscan is tested and measured without hardware, so it is written as a
//! measuring instrument:
//! * every pixel's rays come from the exact camera model (any [`omni_model::CameraModel`], via
//!   `pixel_to_ray`); pixels near a stripe, an object edge, a checkerboard edge or the mirror rim
//!   are supersampled (8 × 8 by default), the others take the mean of their corners;
//! * the laser sheet has a Gaussian profile across the light plane (FWHM 0.5 mm), box-filtered
//!   analytically over each sample's footprint so a sheet far thinner than a pixel is not
//!   aliased, scaled by incidence angle, albedo and the 1/r spreading of the 180° fan; laser
//!   shadows (path from the facet to the point) and camera occlusions are honoured;
//! * the optical PSF acts on the continuous image before the pixels integrate it (each sample is
//!   spread from its own sub-pixel position); the lens ([`Optics`]) sets it from diffraction and
//!   defocus, and images the laser coherently through its pupil, so that laser speckle follows
//!   from the physics. The defocus is one figure for the frame, or, with the lens focused at a
//!   distance ([`Optics::focus_mm`]), each pixel's own as the mirror's curved virtual image makes
//!   it (per pixel for incoherent light, per 16 px tile for the laser's); then photon (Poisson)
//!   and read noise,
//!   saturation, gamma and quantisation, deterministic for a seed (a self-contained SplitMix64);
//! * scene lighting (level, gradients, hard-edged patches) and textured albedo; optional motion
//!   blur (the polygon turning during the exposure);
//! * off by default, stripes as real sensors show them (issue 33, docs/DECISIONS.md "Real stripe
//!   cross-sections"): the measured lopsided cross-section ([`SheetProfile::real`], its peak on
//!   the light plane) at a width set in pixels ([`RenderOptions::stripe_fwhm_px`]), blooming
//!   ([`Bloom`]) and glare ([`Halo`]), a colour camera ([`Colour`]: Bayer mosaic, filter
//!   responses, white balance, colour matrix; RGB frames or the raw mosaic) and JPEG frames with
//!   4:2:0 chroma ([`FrameFormat`], [`render_sweep_as`]).
//!
//! [`RenderOptions::default`] is the realistic sensor: a real industrial 8-bit monochrome camera
//! (full well 10 000 e⁻, read noise 6 e⁻, 8 bits over the full well ≈ 39 e⁻/DN, gamma 1) behind
//! an F/4 lens on 4.65 µm pixels with a 650 nm laser ([`Optics::paper`]), laser speckle, a
//! mid-bright room. [`RenderOptions::ideal`] is the idealised sensor (Gaussian PSF σ 0.7 px, no
//! speckle, a dim room), with its harder conditions [`RenderOptions::ideal_saturated`],
//! [`RenderOptions::ideal_weak_stripe`] and [`RenderOptions::ideal_strong_ambient`];
//! [`RenderOptions::calibration`] lights the room for checkerboards. A scaled-down sensor sees
//! each pixel's footprint grow, so its stripes are dimmer. [`error_budget`] predicts the
//! per-point σ the sensor allows.
//!
//! The sensor ([`Sensor::paper`]): the paper's mirror (a² = 1248.2060 mm², b² = 351.7940 mm²,
//! c = 40 mm), 1024 × 1024 px, f = 1950 px, rim radius 25 mm; a 12-facet polygon of
//! circumradius 20 mm whose axis is 120 mm below the camera centre. [`Sensor::paper_scaled`]
//! gives the same sensor with a smaller image for fast tests; [`paper_preset`] adds build errors.
//!
//! Ground truth ([`TruthPoint`], [`stripe_truth`], [`truth_polylines`], [`sheet_gradient_at`]
//! for the direction across a stripe): the reflected fan of
//! each laser sampled from its virtual source, first scene hit, kept if lit and seen; exact
//! pixels by `point_to_pixel`, samples ≤ 0.25 px apart along each curve. Tests check that truth
//! pixels triangulate onto the surface within 1e-6 mm and that the noiseless rendered stripe's
//! centroid lies within 0.05 px of the truth curve.
//!
//! Boards ([`render_board_image`], [`random_board_poses`], [`Rig`]): board frame as OpenCV —
//! origin at the top-left inner corner, x along columns, y down the rows, z into the board;
//! corner `i` at (i % cols, i / cols) · square.
//!
//! ```
//! use omni_simulator::{BenchObject, RenderOptions, Scene, Sensor, paper_bench, render_laser_frame};
//! let sensor = Sensor::paper_scaled(128);
//! let scene = Scene::from_file(paper_bench(BenchObject::Plane)).unwrap();
//! let frame = render_laser_frame(&sensor, &scene, 15f64.to_radians(), 0, &[0, 1], &RenderOptions::default());
//! assert_eq!(frame.image.width, 128);
//! assert!(!frame.truth.is_empty());
//! ```

mod bench;
mod boards;
mod budget;
mod capture;
mod coherent;
#[cfg(test)]
mod focus_tests;
mod frame;
mod profile;
mod render;
pub use omni_geom::rng;
mod scene;
mod sensor;
mod sequence;
#[cfg(test)]
mod stripe_tests;
mod tools;
mod truth;

pub use bench::{BENCH_ALBEDO, BenchObject, paper_bench};
pub use boards::{
    BoardPose, Rig, board_object, calibration_board_poses, corner_pixels, random_board_poses, render_board_image,
    render_rig_pose_image,
};
pub use budget::{BudgetLine, CalibrationUncertainty, calibration_from_reports, error_budget, speckle_sigma_px};
pub use capture::{Bloom, BloomAxis, Colour, ColourOutput, Halo, bloom_line};
pub use frame::{Frame16, FrameFormat, RgbFrame};
pub use omni_model::{BayerPattern, CameraColour, Optics, filter_response};
pub use profile::{GAUSS_FWHM_PER_SIGMA, SheetProfile};
pub use render::{
    CALIBRATION_AMBIENT_E, DEFAULT_LASER_STRENGTH, Imaging, LaserFrame, REALISTIC_AMBIENT_E, REALISTIC_LASER_STRENGTH,
    RenderOptions, TruthPoint, blurred_peak_at, render_ambient_frame, render_ambient_images, render_laser_frame,
    sheet_gradient_at,
};
pub use scene::{Hit, Scene, board_corners};
pub use sensor::{Sensor, paper_camera_scaled};
pub use sequence::{RenderedFrame, Sweep, render_sweep, render_sweep_as, write_manifest, write_truth};
pub use tools::{Imperfections, TruthRecord, check_boards_visible, paper_preset, parse_angles, truth_header};
pub use truth::{stripe_truth, truth_point, truth_polylines};
