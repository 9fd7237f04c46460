#!/usr/bin/env python3
"""The receiver's camera models beside OpenCV's on the same detected corners.

omni-calib-receiver detects the corners once (--save-corners) and fits each model to that file
(--corners): its default robust fit (Huber loss, image weights, outlier images left out) and
--least-squares (the plain sum of squares OpenCV minimises). OpenCV fits the same corners:
calibrateCamera (k1 k2 p1 p2 k3; k1 k2 p1 p2 with CALIB_FIX_K3; the rational model) and
cv2.fisheye.calibrate (CALIB_RECOMPUTE_EXTRINSIC | CALIB_FIX_SKEW). Every RMS is per corner
(Euclidean), over the corners of the images each fit used, OpenCV's recomputed with projectPoints.

Used by scripts/real_plane.py (its table) and by bin/omni-calib-receiver/tests/interop.py (the
assertions); alone: scripts/receiver_models.py --bin DIR --board board.json IMAGES...
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np

# omniscan models: (name shown, --model, extra arguments).
OMNISCAN_FITS = [
    ("mei", "mei", []),
    ("pinhole", "pinhole", []),
    ("pinhole-radtan", "pinhole-radtan", []),
    ("fisheye", "fisheye", []),
    ("mei --least-squares", "mei", ["--least-squares"]),
    ("pinhole --least-squares", "pinhole", ["--least-squares"]),
    ("pinhole-radtan --least-squares", "pinhole-radtan", ["--least-squares"]),
    ("fisheye --least-squares", "fisheye", ["--least-squares"]),
]


def detect(bin_dir: Path, board: Path, images: list[str], corners: Path) -> None:
    """Corners of the images by omni-calib-receiver (a Mei fit, whose camera.json is dropped)."""
    cmd = [str(bin_dir / "omni-calib-receiver"), "--board", str(board), "--save-corners", str(corners),
           "-o", str(corners.with_suffix(".mei.json")), *images]
    p = subprocess.run(cmd, capture_output=True, text=True)
    if p.returncode != 0 or not corners.exists():
        sys.exit(f"receiver_models.py: corner detection failed: {p.stderr.strip()}")


def omniscan_fit(bin_dir: Path, board: Path, corners: Path, model: str, extra: list[str], out: Path) -> dict:
    """One fit to the corners file: {rms, images, warning} or {error}."""
    cmd = [str(bin_dir / "omni-calib-receiver"), "--board", str(board), "--corners", str(corners),
           "--model", model, *extra, "-o", str(out)]
    p = subprocess.run(cmd, capture_output=True, text=True)
    if p.returncode != 0:
        return {"error": p.stderr.strip().splitlines()[-1] if p.stderr.strip() else f"exit {p.returncode}"}
    report = json.loads(out.read_text())["report"]
    return {"rms": report["rms_per_corner_px"], "images": report["images_used"],
            "warning": any("Mei model leaves" in w for w in report["warnings"])}


def load_corners(corners: Path, square_mm: float):
    d = json.loads(corners.read_text())
    obj, img = [], []
    for im in d["images"]:
        c = np.array(im["corners"], float)
        if len(c) == 0:
            continue
        obj.append(np.c_[c[:, 0] * square_mm, c[:, 1] * square_mm, np.zeros(len(c))].reshape(-1, 1, 3))
        img.append(c[:, 2:4].reshape(-1, 1, 2))
    return (d["width"], d["height"]), obj, img


def opencv_fits(corners: Path, square_mm: float) -> dict[str, dict]:
    """OpenCV's models on the same corners: name -> {rms, images} or {error}."""
    size, obj, img = load_corners(corners, square_mm)
    n = sum(len(o) for o in obj)
    crit = (cv2.TERM_CRITERIA_COUNT + cv2.TERM_CRITERIA_EPS, 200, 1e-12)
    out = {}
    for name, flags in (("opencv pinhole", 0), ("opencv pinhole k3=0", cv2.CALIB_FIX_K3),
                        ("opencv rational", cv2.CALIB_RATIONAL_MODEL)):
        try:
            _, K, D, rv, tv = cv2.calibrateCamera([o.astype(np.float32) for o in obj],
                                                  [i.astype(np.float32) for i in img], size, None, None,
                                                  flags=flags, criteria=crit)
            err = sum(np.sum((cv2.projectPoints(o, r, t, K, D)[0] - i) ** 2)
                      for o, i, r, t in zip(obj, img, rv, tv))
            out[name] = {"rms": float(np.sqrt(err / n)), "images": len(obj)}
        except cv2.error as e:
            out[name] = {"error": str(e).strip().splitlines()[-1]}
    try:
        flags = cv2.fisheye.CALIB_RECOMPUTE_EXTRINSIC | cv2.fisheye.CALIB_FIX_SKEW
        _, K, D, rv, tv = cv2.fisheye.calibrate(obj, img, size, None, None, flags=flags, criteria=crit)
        err = sum(np.sum((cv2.fisheye.projectPoints(o, r, t, K, D)[0] - i) ** 2)
                  for o, i, r, t in zip(obj, img, rv, tv))
        out["opencv fisheye"] = {"rms": float(np.sqrt(err / n)), "images": len(obj)}
    except cv2.error as e:
        out["opencv fisheye"] = {"error": str(e).strip().splitlines()[-1]}
    return out


def compare(bin_dir: Path, board: Path, images: list[str], out: Path, square_mm: float) -> dict[str, dict]:
    """Every fit of OMNISCAN_FITS and opencv_fits on one detection: name -> result."""
    out.mkdir(parents=True, exist_ok=True)
    corners = out / "corners.json"
    detect(bin_dir, board, images, corners)
    rows = {}
    for name, model, extra in OMNISCAN_FITS:
        tag = name.replace(" --least-squares", "-ls")
        rows[f"omniscan {name}"] = omniscan_fit(bin_dir, board, corners, model, extra, out / f"camera-{tag}.json")
    rows.update(opencv_fits(corners, square_mm))
    return rows


def print_table(title: str, rows: dict[str, dict]) -> None:
    print(title)
    print(f"  {'model':<40} {'images':>6} {'rms_px':>9}")
    for name, r in rows.items():
        if "error" in r:
            print(f"  {name:<40} {'-':>6} {'-':>9}  failed: {r['error'][:90]}")
        else:
            note = "  (warns: Mei fits clearly better)" if r.get("warning") else ""
            print(f"  {name:<40} {r['images']:>6} {r['rms']:>9.4f}{note}")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--bin", type=Path, required=True, help="directory of omni-calib-receiver")
    ap.add_argument("--board", type=Path, required=True, help="board.json")
    ap.add_argument("--out", type=Path, default=Path("out/receiver-models"))
    ap.add_argument("images", nargs="+")
    a = ap.parse_args()
    square = json.loads(a.board.read_text())["square_mm"]
    print_table("receiver RMS per corner (px), same corners:", compare(a.bin, a.board, a.images, a.out, square))
    return 0


if __name__ == "__main__":
    sys.exit(main())
