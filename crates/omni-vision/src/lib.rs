//! Image processing for omniscan: laser-stripe centres ([`stripe`]), checkerboard corners
//! ([`corners`]) and image I/O helpers ([`image_io`]).

pub mod colour;
pub mod corners;
pub mod image_io;
pub mod rim;
pub mod stripe;
