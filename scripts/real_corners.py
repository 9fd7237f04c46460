#!/usr/bin/env python3
"""omniscan's checkerboard corners against OpenCV's on real images, judged by the same model.

For each real set (read in place from ../shared/data, never copied), OpenCV finds the board in
every image (`findChessboardCorners` with adaptive threshold + normalise, and
`findChessboardCornersSB` with its accuracy flag; each refined by `cornerSubPix` at winSize
(w, w) for w = 3, 5, 7, 11, i.e. windows 7-23 px wide, 100 iterations or 0.001 px; and SB's own
corners as they come), and omniscan's detector finds it through
`omni-calib-receiver --save-corners`. On the boards both find, each OpenCV corner takes the label
of the omniscan corner it lies on (so that the labels, and the mirroring the receiver decides,
are the same), and only corners both have are kept. Both corner sets are then fitted with the
same omniscan Mei model (`omni-calib-receiver --corners`), and the table gives, per OpenCV
variant: boards in common, corner differences (median and 90th percentile, px) and the RMS per
corner (Euclidean, px) of each fit.

Usage: scripts/real_corners.py --bin DIR [--set miniomni|handheld] [--json FILE]
The pytest test (bin/omni-calib-receiver/tests/test_real_corners.py, `make test-calib-interop`)
imports `judge`.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

ROOT = Path(__file__).resolve().parent.parent
SHARED = ROOT.parent / "shared" / "data"


@dataclass(frozen=True)
class RealSet:
    name: str
    directory: Path
    images: tuple[str, ...]
    cols: int
    rows: int
    square_mm: float


SETS = {
    "miniomni": RealSet("miniomni", SHARED / "real-omni-miniomni",
                        tuple(f"MiniOmni{k}.jpg" for k in range(1, 16)), 7, 11, 30.0),
    "handheld": RealSet("handheld", SHARED / "real-laser-handheld",
                        tuple(f"im{k}.png" for k in range(18, 37)), 9, 6, 5.0),
}

# cornerSubPix: iterate until the step is below 0.001 px or 100 iterations (OpenCV's tightest
# useful criteria; the default 30 iterations / 0.1 px stops early on blurred corners).
CRITERIA = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 100, 1e-3)
# Half window sizes (winSize = (w, w), the window is 2w + 1 px wide) tried with cornerSubPix.
HALF_WINDOWS = (3, 5, 7, 11)
# An OpenCV corner is the same corner as omniscan's when within this distance (px).
MATCH_PX = 3.0


def opencv_variants(gray: np.ndarray, cols: int, rows: int) -> dict[str, np.ndarray | None]:
    """OpenCV's corners of one image per variant (N x 2 arrays, or None where not found): each
    detector's corners refined by cornerSubPix at each of HALF_WINDOWS, and SB's own."""
    flags = cv2.CALIB_CB_ADAPTIVE_THRESH + cv2.CALIB_CB_NORMALIZE_IMAGE
    ok, classic = cv2.findChessboardCorners(gray, (cols, rows), flags=flags)
    ok_sb, sb = cv2.findChessboardCornersSB(gray, (cols, rows), flags=cv2.CALIB_CB_ACCURACY)
    out: dict[str, np.ndarray | None] = {"SB": sb.reshape(-1, 2).astype(np.float64) if ok_sb else None}
    for name, found, start in (("classic", ok, classic), ("SB", ok_sb, sb)):
        for w in HALF_WINDOWS:
            c = cv2.cornerSubPix(gray, start.copy(), (w, w), (-1, -1), CRITERIA) if found else None
            out[f"{name}+subpix{w}"] = None if c is None else c.reshape(-1, 2).astype(np.float64)
    return out


def best_subpix(result: dict) -> tuple[str, dict]:
    """The cornerSubPix variant with the lowest Mei RMS (the best OpenCV's refinement does)."""
    return min(((v, r) for v, r in result["variants"].items() if "subpix" in v), key=lambda vr: vr[1]["rms_opencv_px"])


def run(cmd: list[str]) -> None:
    p = subprocess.run(cmd, capture_output=True, text=True)
    if p.returncode != 0:
        sys.exit(f"real_corners.py: {Path(cmd[0]).name} failed (exit {p.returncode}): {p.stderr.strip()}")


def board_file(s: RealSet, path: Path) -> Path:
    path.write_text(json.dumps({"format": "omniscan.board", "version": 1, "inner_cols": s.cols,
                                "inner_rows": s.rows, "square_mm": s.square_mm, "margin_mm": 0}))
    return path


def omniscan_corners(receiver: Path, s: RealSet, work: Path) -> dict:
    """omniscan's corners file of the set (detection by omni-calib-receiver)."""
    out = work / f"{s.name}_omniscan_all.json"
    run([str(receiver), "--board", str(board_file(s, work / f"{s.name}_board.json")), "--save-corners", str(out),
         "-o", str(work / f"{s.name}_detect_cam.json"), *[str(s.directory / n) for n in s.images]])
    return json.loads(out.read_text())


def fit_rms(receiver: Path, s: RealSet, corners: dict, work: Path, tag: str) -> tuple[float, int]:
    """(RMS per corner in px, images used) of the Mei fit to a corners file."""
    path = work / f"{s.name}_{tag}.json"
    path.write_text(json.dumps(corners))
    cam = work / f"{s.name}_{tag}_cam.json"
    run([str(receiver), "--board", str(work / f"{s.name}_board.json"), "--corners", str(path), "--model", "mei",
         "-o", str(cam)])
    report = json.loads(cam.read_text())["report"]
    return report["rms_per_corner_px"], report["images_used"]


def matched(omni: list[list[float]], cv: np.ndarray) -> tuple[list[list[float]], list[list[float]]]:
    """The corners both have: omniscan's, and OpenCV's under omniscan's labels."""
    mine, theirs = [], []
    for c in omni:
        d = np.hypot(cv[:, 0] - c[2], cv[:, 1] - c[3])
        k = int(np.argmin(d))
        if d[k] <= MATCH_PX:
            mine.append(c)
            theirs.append([c[0], c[1], float(cv[k, 0]), float(cv[k, 1])])
    return mine, theirs


def judge(receiver: Path, name: str) -> dict:
    """Per OpenCV variant: boards both find, corner differences, both Mei RMS (see the module)."""
    s = SETS[name]
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        omni = omniscan_corners(receiver, s, work)
        by_name = {Path(i["name"]).name: i for i in omni["images"]}
        found_omni = sum(1 for i in omni["images"] if i["corners"])
        variants: dict[str, list] = {}
        for n in s.images:
            gray = cv2.imread(str(s.directory / n), cv2.IMREAD_GRAYSCALE)
            if gray is None:
                sys.exit(f"real_corners.py: {s.directory / n}: cannot read")
            for v, cv in opencv_variants(gray, s.cols, s.rows).items():
                variants.setdefault(v, []).append((n, cv))
        rows = {}
        for v, per_image in variants.items():
            mine_imgs, theirs_imgs, diffs = [], [], []
            for n, cv in per_image:
                entry = by_name.get(n)
                if cv is None or entry is None or not entry["corners"]:
                    continue
                mine, theirs = matched(entry["corners"], cv)
                if len(mine) < 12:
                    continue
                mine_imgs.append({"name": n, "corners": mine})
                theirs_imgs.append({"name": n, "corners": theirs})
                diffs.append(np.hypot(*(np.array(mine)[:, 2:] - np.array(theirs)[:, 2:]).T))
            base = {k: omni[k] for k in ("format", "version", "width", "height", "inner_cols", "inner_rows")}
            rms_omni, used_omni = fit_rms(receiver, s, {**base, "images": mine_imgs}, work, f"{v}_omni")
            rms_cv, used_cv = fit_rms(receiver, s, {**base, "images": theirs_imgs}, work, f"{v}_cv")
            d = np.concatenate(diffs)
            rows[v] = {"found_opencv": sum(1 for _, cv in per_image if cv is not None), "common": len(mine_imgs),
                       "corners": int(d.size), "diff_median_px": float(np.median(d)),
                       "diff_p90_px": float(np.percentile(d, 90)), "rms_omniscan_px": rms_omni,
                       "rms_opencv_px": rms_cv, "used_omniscan": used_omni, "used_opencv": used_cv}
        return {"set": name, "images": len(s.images), "found_omniscan": found_omni, "variants": rows}


def print_table(result: dict) -> None:
    print(f"{result['set']}: omniscan finds {result['found_omniscan']} of {result['images']} boards")
    print(f"  {'OpenCV variant':<18} {'found':>5} {'common':>6} {'corners':>7} {'diff med':>8} {'p90':>6} "
          f"{'RMS omniscan':>12} {'RMS OpenCV':>10}")
    for v, r in result["variants"].items():
        print(f"  {v:<18} {r['found_opencv']:>5} {r['common']:>6} {r['corners']:>7} {r['diff_median_px']:>8.3f} "
              f"{r['diff_p90_px']:>6.3f} {r['rms_omniscan_px']:>12.4f} {r['rms_opencv_px']:>10.4f}")
    v, r = best_subpix(result)
    print(f"  best cornerSubPix: {v}: omniscan {r['rms_omniscan_px']:.4f} px, OpenCV {r['rms_opencv_px']:.4f} px "
          f"on the same {r['common']} boards, {r['corners']} corners")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--bin", type=Path, required=True, help="directory with omni-calib-receiver")
    ap.add_argument("--set", choices=sorted(SETS), action="append", help="set(s) to judge (default: all)")
    ap.add_argument("--json", type=Path, help="also write the results here")
    a = ap.parse_args()
    results = [judge(a.bin / "omni-calib-receiver", n) for n in (a.set or sorted(SETS))]
    for r in results:
        print_table(r)
    if a.json:
        a.json.write_text(json.dumps(results, indent=1))


if __name__ == "__main__":
    main()
