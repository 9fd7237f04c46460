//! The virtual sensor: scenes and physically based rendering of laser and checkerboard frames with ground truth.
