#!/usr/bin/env python3
"""Reference implementation of the paper's stripe centre (threshold + intensity centroid,
Eq. 16) sampled radially from the mirror centre, in numpy + OpenCV, for comparison with
omni-ridge's `centroid` estimator (crates/omni-vision/benches/ridge.rs).

The frame is resampled to polar coordinates with cv2.warpPolar (bilinear, 1 px in radius, one
row per ≤ 1 px of rim), samples at or below the threshold are zeroed, and every run of
consecutive samples above it along a row gives one centroid (vectorised with np.add.reduceat).

Usage: bench_ridge.py FRAME.png [FRAME.png ...] [--centre CX CY] [--radii R_IN R_OUT]
                      [--threshold T] [--runs N]
Prints one line per frame: `PYTHON <name> <ms per megapixel> ms/MP (<points> points)`, the median
of this thread's CPU time per run.
Install: pip install numpy opencv-python-headless
"""

import argparse
import math
import os
import sys
import time

try:
    import cv2
    import numpy as np
except ImportError:
    sys.exit("bench_ridge.py: needs numpy and OpenCV: pip install numpy opencv-python-headless")


def stripe_centres(img, centre, r_in, r_out, threshold):
    """Stripe centres (u, v) of one frame: radial threshold + intensity centroid."""
    n_rays = int(math.ceil(2 * math.pi * r_out))
    n_r = int(math.ceil(r_out))
    polar = cv2.warpPolar(img, (n_r, n_rays), centre, r_out, cv2.INTER_LINEAR + cv2.WARP_POLAR_LINEAR)
    polar = polar.astype(np.float32)
    polar[:, : int(r_in)] = 0
    weights = np.where(polar > threshold, polar, 0).astype(np.float32)
    above = weights > 0
    # Run starts and ends along each row (a run never crosses rows: the last column is cleared).
    above[:, -1] = False
    flat_w = weights.ravel()
    flat_a = above.ravel()
    edges = np.diff(flat_a.astype(np.int8), prepend=0)
    starts = np.flatnonzero(edges == 1)
    ends = np.flatnonzero(edges == -1)
    if len(starts) == 0:
        return np.empty((0, 2))
    radius = np.tile(np.arange(n_r, dtype=np.float32) * (r_out / n_r), n_rays)
    bounds = np.stack([starts, ends], axis=1).ravel()
    sw = np.add.reduceat(flat_w, bounds)[::2]
    swr = np.add.reduceat(flat_w * radius, bounds)[::2]
    r = swr / sw
    rows = starts // n_r
    phi = rows * (2 * math.pi / n_rays)
    return np.stack([centre[0] + r * np.cos(phi), centre[1] + r * np.sin(phi)], axis=1)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("frames", nargs="+")
    ap.add_argument("--centre", nargs=2, type=float, default=None, help="mirror centre (px); default image centre")
    ap.add_argument("--radii", nargs=2, type=float, default=None, help="annulus radii (px)")
    ap.add_argument("--threshold", type=float, default=60.0, help="intensity threshold (default 60 of 255)")
    ap.add_argument("--runs", type=int, default=30)
    args = ap.parse_args()
    cv2.setNumThreads(1)  # one core, like the Rust benchmark
    for path in args.frames:
        img = cv2.imread(path, cv2.IMREAD_UNCHANGED)
        if img is None:
            sys.exit(f"bench_ridge.py: {path}: not a readable image")
        h, w = img.shape[:2]
        centre = tuple(args.centre) if args.centre else ((w - 1) / 2, (h - 1) / 2)
        r_in, r_out = args.radii if args.radii else (0.0, (min(w, h) - 1) / 2)
        times = []
        # This thread's CPU time per run (median), as the Rust benchmark's figure the ratio uses:
        # other processes competing for the cores do not inflate it.
        for _ in range(args.runs):
            t = time.thread_time()
            pts = stripe_centres(img, centre, r_in, r_out, args.threshold)
            times.append(time.thread_time() - t)
        times.sort()
        ms_per_mp = 1e3 * times[len(times) // 2] / (w * h / 1e6)
        name = os.path.splitext(os.path.basename(path))[0]
        print(f"PYTHON {name} {ms_per_mp:.3f} ms/MP ({len(pts)} points)")


if __name__ == "__main__":
    main()
