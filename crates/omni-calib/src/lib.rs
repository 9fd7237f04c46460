//! Calibration for omniscan: the receiver (catadioptric camera, [`receiver`]) from checkerboard
//! images, and the transmitter (swept light planes, [`plane`]) from two perpendicular boards.

pub mod plane;
pub mod pose;
pub mod receiver;
