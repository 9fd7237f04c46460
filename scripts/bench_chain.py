#!/usr/bin/env python3
"""Stripes to points, the whole chain, on realistic 1 MP room frames (`make bench`; issue "Speed
toward the memory limit").

Renders the paper sensor's realistic room scan once (60 frames of 1024 x 1024, two stripes all
around the image: the dense case), replays it `--repeat` times as one stream and runs

    omni-ridge --camera --binary | omni-triangulate --binary > /dev/null

from PGM files in the page cache, then the same with JSON Lines streams and from PNG files.
Prints per variant: frames/s by the wall clock, CPU per frame of each tool, and the rate 2 free
cores would sustain (frames / (CPU / 2), what the wall clock shows on a quiet machine when both
cores are used). For PNG, the share of the CPU outside decoding, estimated as the PGM chain's CPU
over the PNG chain's (a PGM read is a copy, so the difference is the PNG decoder).

Usage: scripts/bench_chain.py [--bin DIR] [--repeat N] [--runs K]
"""

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
ROOM = {"format": "omniscan.scene", "version": 1,
        "objects": [{"name": "room", "albedo": 0.8, "type": "room", "centre_mm": [0, 0, 0],
                     "size_mm": [1600, 1600, 1000]}]}


def render(sim: str, work: Path, fmt: str) -> Path:
    if not (work / "sensor").exists():
        subprocess.run([sim, "sensor", "--preset", "paper", "-o", work / "sensor"], check=True, capture_output=True)
        (work / "room.json").write_text(json.dumps(ROOM))
    manifest = work / f"room_{fmt}.jsonl"
    subprocess.run([sim, "scan", "--camera", work / "sensor/camera.json", "--scanner", work / "sensor/scanner.json",
                    "--scene", work / "room.json", "--angles", "14:29:0.25", "--format", fmt,
                    "--frames", work / f"room_{fmt}", "-o", manifest], check=True, capture_output=True)
    return manifest


def replay(manifest: Path, repeat: int) -> Path:
    """The scan's frames `repeat` times over, as revolutions of one stream."""
    lines = manifest.read_text().splitlines()
    frames = [json.loads(x) for x in lines[1:] if json.loads(x)["type"] == "frame"]
    out = [lines[0]]
    for r in range(repeat):
        out += [json.dumps(dict(f, seq=r * len(frames) + f["seq"], revolution=r)) for f in frames]
    out.append(json.dumps({"type": "status", "frames": repeat * len(frames), "frames_missing": 0,
                           "complete": True, "errors": []}))
    path = manifest.with_name(manifest.stem + "_replay.jsonl")
    path.write_text("\n".join(out) + "\n")
    return path


def run_chain(bin_dir: Path, work: Path, stream: Path, binary: bool) -> dict:
    cam = ["--camera", str(work / "sensor/camera.json")]
    flag = ["--binary"] if binary else []
    t0 = time.monotonic()
    ridge = subprocess.Popen([str(bin_dir / "omni-ridge"), *cam, *flag, str(stream)], stdout=subprocess.PIPE)
    tri = subprocess.Popen([str(bin_dir / "omni-triangulate"), *cam, *flag,
                            "--scanner", str(work / "sensor/scanner.json")],
                           stdin=ridge.stdout, stdout=subprocess.DEVNULL)
    ridge.stdout.close()
    cpu = {}
    for name, p in (("omni-ridge", ridge), ("omni-triangulate", tri)):
        _, status, usage = os.wait4(p.pid, 0)
        if os.waitstatus_to_exitcode(status) != 0:
            sys.exit(f"bench_chain.py: {name} failed on {stream}")
        p.returncode = 0
        cpu[name] = usage.ru_utime + usage.ru_stime
    return {"wall": time.monotonic() - t0, **cpu}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--bin", default=str(ROOT / "target/release"))
    ap.add_argument("--repeat", type=int, default=20, help="times the 60-frame scan is replayed")
    ap.add_argument("--runs", type=int, default=3, help="runs per variant; the fastest is reported")
    args = ap.parse_args()
    bin_dir = Path(args.bin)
    work = Path(tempfile.mkdtemp(prefix="omni-chain-bench-"))
    try:
        streams = {fmt: replay(render(str(bin_dir / "omni-sim"), work, fmt), args.repeat) for fmt in ("pgm", "png")}
        n = 60 * args.repeat
        for d in ("room_pgm", "room_png"):  # into the page cache
            for f in (work / d).iterdir():
                f.read_bytes()
        results = {}
        for label, fmt, binary in (("PGM, binary streams", "pgm", True), ("PGM, JSON streams", "pgm", False),
                                   ("PNG, binary streams", "png", True)):
            runs = [run_chain(bin_dir, work, streams[fmt], binary) for _ in range(args.runs)]
            best = min(runs, key=lambda r: r["omni-ridge"] + r["omni-triangulate"])
            cpu = best["omni-ridge"] + best["omni-triangulate"]
            results[label] = cpu
            print(f"{label}: {n} frames, {n / min(r['wall'] for r in runs):.0f} frames/s by the wall clock; "
                  f"CPU per frame omni-ridge {1e3 * best['omni-ridge'] / n:.3f} ms, "
                  f"omni-triangulate {1e3 * best['omni-triangulate'] / n:.3f} ms; "
                  f"2 free cores sustain {n / (cpu / 2):.0f} frames/s (target >= 1000 from PGM)")
        share = results["PGM, binary streams"] / results["PNG, binary streams"]
        print(f"PNG: share of the chain's CPU outside PNG decoding {100 * share:.0f} % (target <= 30 %)")
    finally:
        shutil.rmtree(work, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
