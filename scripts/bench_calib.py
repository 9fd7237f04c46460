#!/usr/bin/env python3
"""Receiver calibration side by side: omniscan (omni-calib-receiver) vs OpenCV's omnidir.

Both fit the unified (Mei) model to exactly the same corners, detected by omni-calib-receiver:
  * the real MiniOmni images (../shared/data/real-omni-miniomni, 7 x 11 corners): RMS only;
  * the simulated set written by `cargo bench -p omni-calib --bench receiver`
    ($CARGO_TARGET_DIR/receiver-bench, default target/: 20 images of 1024 x 1024, 9 x 6 corners, true camera known):
    RMS and the ray error of each fitted model against the true hyperbolic camera, over the whole
    mirror image and after the best common rotation (Kabsch: board images cannot observe the
    camera frame's rotation, every board pose absorbs it). The mirror annulus written by the
    benchmark (annulus.txt) is given to omni-calib-receiver (--annulus) for this set.

Needs: pip install opencv-contrib-python-headless numpy; a built omni-calib-receiver
(cargo build --release -p omni-calib-receiver; found in $CARGO_TARGET_DIR or target/).

Frames: OpenCV's omnidir camera looks along +z; omniscan's image centre looks down (-z). Rays are
compared after mapping OpenCV's (x, y, z) to (x, y, -z); intrinsics are the same numbers.
"""

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
REAL = ROOT.parent / "shared" / "data" / "real-omni-miniomni"


def find_binary():
    names = []
    for base in [os.environ.get("CARGO_TARGET_DIR"), str(ROOT / "target")]:
        if base:
            names += [Path(base) / "release" / "omni-calib-receiver", Path(base) / "debug" / "omni-calib-receiver"]
    for n in names:
        if n.exists():
            return str(n)
    found = shutil.which("omni-calib-receiver")
    if not found:
        sys.exit("omni-calib-receiver not found: cargo build --release -p omni-calib-receiver")
    return found


def run_ours(binary, board, out_dir, images=None, corners=None, annulus=None):
    cam = Path(out_dir) / "camera.json"
    cmd = [binary, "--board", str(board), "-o", str(cam)]
    if annulus:
        cmd += ["--annulus", annulus]
    if corners:
        cmd += ["--corners", str(corners)]
    else:
        corners = Path(out_dir) / "corners.json"
        cmd += ["--save-corners", str(corners), str(images)]
    subprocess.run(cmd, check=True, stderr=subprocess.DEVNULL)
    return json.loads(cam.read_text()), json.loads(Path(corners).read_text())


def run_opencv(corners, square_mm):
    import cv2

    obj, img = [], []
    for im in corners["images"]:
        c = np.array(im["corners"], dtype=np.float64)
        if len(c) < 8:
            continue
        o = np.zeros((len(c), 1, 3))
        o[:, 0, 0] = c[:, 0] * square_mm
        o[:, 0, 1] = c[:, 1] * square_mm
        obj.append(o)
        img.append(c[:, 2:4].reshape(-1, 1, 2).copy())
    size = (corners["width"], corners["height"])
    crit = (cv2.TERM_CRITERIA_COUNT + cv2.TERM_CRITERIA_EPS, 300, 1e-10)
    rms, K, xi, D, _, _, idx = cv2.omnidir.calibrate(obj, img, size, None, None, None, 0, crit)
    used = 0 if idx is None else int(np.size(idx))
    return float(rms), K, float(np.ravel(xi)[0]), np.ravel(D), used, len(obj)


def mei_rays(px, xi, fx, fy, cx, cy, k1, k2, p1, p2, skew=0.0):
    """Unit rays (omniscan frame, -z at the centre) of pixels under a Mei model."""
    y = (px[:, 1] - cy) / fy
    x = (px[:, 0] - cx - skew * y) / fx
    mx, my = x.copy(), y.copy()
    for _ in range(100):  # fixed-point undistortion
        r2 = mx * mx + my * my
        rad = 1 + k1 * r2 + k2 * r2 * r2
        dx = 2 * p1 * mx * my + p2 * (r2 + 2 * mx * mx)
        dy = p1 * (r2 + 2 * my * my) + 2 * p2 * mx * my
        mx, my = (x - dx) / rad, (y - dy) / rad
    r2 = mx * mx + my * my
    f = (xi + np.sqrt(1 + (1 - xi * xi) * r2)) / (1 + r2)
    d = np.stack([f * mx, f * my, -(f - xi)], axis=1)
    return d / np.linalg.norm(d, axis=1, keepdims=True)


def hyperbolic_rays(px, p):
    """Unit rays of the ideal hyperbolic camera (SENSOR.md closed form), NaN outside the mirror."""
    a, b2 = p["a_mm"], p["b_mm"] ** 2
    c = np.sqrt(a * a + b2)
    u = (px[:, 0] - p["cx_px"]) / p["fx_px"]
    v = (px[:, 1] - p["cy_px"]) / p["fy_px"]
    l = np.hypot(u, v)
    cb = 1 / np.sqrt(1 + l * l)
    sb = l * cb
    om = b2 / (c * cb - a)
    m = np.stack([om * sb * u / l, om * sb * v / l, om * cb], axis=1)
    r = np.hypot(m[:, 0], m[:, 1])
    d = m - np.array([0, 0, 2 * c])
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    d[(r > p["rim_radius_mm"]) | (r < p["inner_radius_mm"])] = np.nan
    return d


def kabsch(a, b):
    """The rotation R minimising sum |R a_i - b_i|^2 (rows are unit vectors)."""
    u, _, vt = np.linalg.svd(a.T @ b)
    d = np.sign(np.linalg.det(vt.T @ u.T))
    return vt.T @ np.diag([1.0, 1.0, d]) @ u.T


def ray_errors(truth, rays_fn):
    """Median and max ray angle (deg) over the mirror annulus, after the best common rotation."""
    phi = np.linspace(0, 2 * np.pi, 72, endpoint=False)
    rad = np.linspace(95, 500, 82)  # pixels outside the mirror are dropped (NaN truth rays)
    rr, pp = np.meshgrid(rad, phi)
    px = np.stack([truth["cx_px"] + rr.ravel() * np.cos(pp.ravel()), truth["cy_px"] + rr.ravel() * np.sin(pp.ravel())], 1)
    t = hyperbolic_rays(px, truth)
    f = rays_fn(px)
    ok = np.all(np.isfinite(t), axis=1) & np.all(np.isfinite(f), axis=1)
    rot = kabsch(f[ok], t[ok])
    ang = np.degrees(np.arccos(np.clip(np.sum(t[ok] * (f[ok] @ rot.T), axis=1), -1, 1)))
    return float(np.median(ang)), float(np.max(ang))


def compare(title, ours, corners, square_mm, truth=None):
    rms_cv, K, xi, D, used_cv, n_cv = run_opencv(corners, square_mm)
    rep = ours["report"]
    print(f"{title}")
    print(f"  omniscan mei : RMS {rep['rms_px']:.3f} px over {rep['images_used']} images")
    print(f"  OpenCV omnidir: RMS {rms_cv:.3f} px over {used_cv} of {n_cv} images")
    if truth is not None:
        m = ours["model"]
        o = ray_errors(truth, lambda px: mei_rays(px, m["xi"], m["fx_px"], m["fy_px"], m["cx_px"], m["cy_px"],
                                                  m["k1"], m["k2"], m["p1"], m["p2"]))
        c = ray_errors(truth, lambda px: mei_rays(px, xi, K[0, 0], K[1, 1], K[0, 2], K[1, 2], D[0], D[1], D[2], D[3],
                                                  skew=K[0, 1]))
        print(f"  rays vs truth: omniscan median {o[0]:.4f} deg, max {o[1]:.4f} deg; "
              f"OpenCV median {c[0]:.4f} deg, max {c[1]:.4f} deg")


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sim-dir", default=str(ROOT / os.environ.get("CARGO_TARGET_DIR", "target") / "receiver-bench"),
                    help="output of the receiver benchmark (corners.json, board.json, truth_camera.json)")
    args = ap.parse_args()
    binary = find_binary()
    with tempfile.TemporaryDirectory() as tmp:
        if REAL.exists():
            board = Path(tmp) / "board.json"
            board.write_text(json.dumps({"format": "omniscan.board", "version": 1, "inner_cols": 7,
                                         "inner_rows": 11, "square_mm": 30.0}))
            ours, corners = run_ours(binary, board, tmp, images=REAL)
            compare("Real MiniOmni images (7 x 11), corners by omni-calib-receiver", ours, corners, 30.0)
        else:
            print(f"skipping real images: {REAL} not found")
        sim = Path(args.sim_dir)
        if (sim / "corners.json").exists():
            board = json.loads((sim / "board.json").read_text())
            truth = json.loads((sim / "truth_camera.json").read_text())["model"]
            annulus = (sim / "annulus.txt").read_text().strip() if (sim / "annulus.txt").exists() else None
            ours, corners = run_ours(binary, sim / "board.json", tmp, corners=sim / "corners.json", annulus=annulus)
            compare("Simulated 20 x 1 MP (9 x 6), paper sensor", ours, corners, board["square_mm"], truth)
        else:
            print(f"skipping simulated set: run `cargo bench -p omni-calib --bench receiver` first ({sim})")


if __name__ == "__main__":
    main()
