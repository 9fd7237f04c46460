//! The virtual sensor: scenes and physically based rendering of laser and checkerboard frames
//! with ground truth.
//!
//! `omni-sim` is how omniscan is tested and measured without hardware, so it is written as a
//! measuring instrument:
//! * every pixel's rays come from the exact camera model ([`omni_model::CameraModel`]), with
//!   adaptive supersampling (8 × 8 for pixels near a stripe or an edge) so that the sub-pixel
//!   stripe profile is right;
//! * the laser sheet has a Gaussian profile across the light plane (FWHM 0.5 mm), scaled by
//!   incidence angle, albedo and the 1/r spreading of the fan; laser shadows and camera
//!   occlusions are honoured;
//! * ambient light, Gaussian optical blur, photon and read noise, saturation, gamma and
//!   quantisation, all deterministic for a seed (a self-contained SplitMix64).
//!
//! Default camera and laser ([`RenderOptions::default`]): an industrial 8-bit monochrome camera
//! with full well 10 000 e⁻, read noise 6 e⁻, gain 255 DN / 10 000 e⁻ (≈ 39 e⁻/DN), gamma 1,
//! PSF σ 0.7 px; a line laser whose sheet is 0.5 mm FWHM and whose stripe peaks at about 190 of
//! 255 on the matte paper-bench plane at 500 mm; dim ambient light (white surface ≈ 51 of 255).
//! The sensor ([`Sensor::paper`]): the paper's mirror (a² = 1248.2060 mm², b² = 351.7940 mm²,
//! c = 40 mm), 1024 × 1024 px, f = 1950 px, rim radius 25 mm; a 12-facet polygon of
//! circumradius 20 mm whose axis is 120 mm below the camera centre.
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
mod frame;
mod render;
pub mod rng;
mod scene;
mod sensor;
mod tools;
mod truth;

pub use bench::{BENCH_ALBEDO, BenchObject, paper_bench};
pub use boards::{
    BoardPose, Rig, board_object, corner_pixels, random_board_poses, render_board_image, render_rig_pose_image,
};
pub use frame::Frame16;
pub use render::{
    CALIBRATION_AMBIENT_E, DEFAULT_LASER_STRENGTH, LaserFrame, RenderOptions, TruthPoint, render_ambient_frame,
    render_laser_frame,
};
pub use scene::{Hit, Scene, board_corners};
pub use sensor::{Sensor, paper_camera_scaled};
pub use tools::{Imperfections, TruthRecord, check_boards_visible, paper_preset, parse_angles, truth_header};
pub use truth::{stripe_truth, truth_point, truth_polylines};
