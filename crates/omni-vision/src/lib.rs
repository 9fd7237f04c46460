//! Image processing: laser-stripe centres, checkerboard corners, image I/O.
