//! Calibration for omniscan: the receiver (catadioptric camera, [`receiver`]) from checkerboard
//! images, and the transmitter: the swept light planes ([`plane`]) from two perpendicular boards,
//! or a fixed light plane ([`fixed_plane`]) from stripe frames with a board in view.

pub mod fixed_plane;
pub mod laser_tail;
pub mod plane;
pub mod pose;
pub mod receiver;
