//! Sensor models for omniscan.
//!
//! * [`CameraModel`]: the receiver, a catadioptric camera, as a map between image pixels and
//!   world rays. Implementations: [`HyperbolicCamera`] (the exact mirror + pinhole model of
//!   SENSOR.md, optionally with the camera off the mirror focus), and the generic calibration
//!   models [`MeiCamera`] (Mei/unified + radial-tangential) and [`OcamCamera`] (Scaramuzza
//!   polynomial, OCamCalib), and for ordinary cameras [`PinholeCamera`] (radial-tangential, as
//!   OpenCV's `calibrateCamera`) and [`FisheyeCamera`] (Kannala–Brandt, as `cv::fisheye`), all
//!   fitted by `omni_calib::receiver`.
//! * [`Transmitter`]: the rotating polygon mirror and its line lasers, giving the world light
//!   plane of any (mirror angle, facet, laser); [`FixedPlanes`]: static light planes (a line
//!   laser rigid with the camera, or the polygon stopped), one per laser.
//!
//! Frames and units (SENSOR.md): world = receiver frame, origin at the camera's optical centre O
//! (the mirror's lower focus), +z up along the optical axis towards the mirror; lengths in mm;
//! angles in radians in code (degrees only in serialised parameters, named `*_deg`).
//! Pixel coordinates: x to the right, y down, (0, 0) at the centre of the top-left pixel.

mod camera;
mod colour;
mod fields;
pub mod fisheye;
mod fixed;
mod hyperbolic;
mod laser_profile;
pub mod limits;
pub mod mei;
pub mod ocam;
mod optics;
pub mod pinhole;
mod transmitter;

pub use fixed::{FixedPlaneParams, FixedPlanes, FixedPlanesParams, TransmitterModel};

pub use camera::{CameraModel, CentralCamera, CentralParams, MirrorCircle};
pub use colour::{BayerPattern, CameraColour, filter_response};
pub use fisheye::{FisheyeCamera, FisheyeParams};
pub use hyperbolic::{DefocusSpot, HyperbolicCamera, HyperbolicParams};
pub use laser_profile::{GAUSS_FWHM_PER_SIGMA, LaserProfile};
pub use mei::{MeiCamera, MeiParams};
pub use ocam::{OcamCamera, OcamParams};
pub use optics::Optics;
pub use pinhole::{PinholeCamera, PinholeParams};
pub use transmitter::{FacetError, LaserParams, LightPlane, PolygonParams, Transmitter, TransmitterParams};

/// `scanner.json`'s name of the rotating polygon transmitter ([`Transmitter`]).
pub const TRANSMITTER_KIND_POLYGON: &str = "polygon";
/// `scanner.json`'s name of the fixed-plane transmitter ([`FixedPlanes`]).
pub const TRANSMITTER_KIND_FIXED_PLANES: &str = "fixed_planes";
