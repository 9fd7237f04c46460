"""omniscan in Python: the omniscan crates' camera and scanner models, triangulation, stripe
detector and readers on numpy arrays (a thin layer: every computation is the Rust crates').

Units as in every omniscan file: millimetres, world frame (+z up towards the mirror), degrees
for angles, pixels x right and y down with (0, 0) at the centre of the top-left pixel.

    import omniscan
    cam = omniscan.Camera.load("calib/camera.json")
    scanner = omniscan.Scanner.load("calib/scanner.json")
    stripe = omniscan.detect_stripe(image, cam)           # (n, 5): u, v, intensity, width, quality
    pts = omniscan.triangulate(cam, scanner, stripe[:, :2], alpha_deg=20.0, facet=0)
    pts["xyz"]                                              # (m, 3) mm
"""

from ._native import (
    DEFAULT_MIN_INCIDENCE_DEG,
    Camera,
    FormatError,
    Scanner,
    detect_stripe,
    measure_laser_tail,
    read_ply,
    read_stream,
    triangulate,
)

__all__ = [
    "DEFAULT_MIN_INCIDENCE_DEG",
    "Camera",
    "FormatError",
    "Scanner",
    "detect_stripe",
    "measure_laser_tail",
    "read_ply",
    "read_stream",
    "triangulate",
]
