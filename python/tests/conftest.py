"""Shared fixtures: the omniscan tools (OMNISCAN_BIN, default target/debug) and a tiny
simulated scan made with them, the ground truth of the binding tests."""
import json
import os
import subprocess

import pytest

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
BIN = os.environ.get("OMNISCAN_BIN", os.path.join(REPO, "target", "debug"))
# A small image and a few mirror angles of the idealised sensor (no speckle) keep the rendering
# to seconds and the stripes clear at that size.
WIDTH = 384
ANGLES = "15:29:2"


def tool(name):
    path = os.path.join(BIN, name)
    if not os.access(path, os.X_OK):
        pytest.fail(f"{path} is missing: build the tools first (cargo build), or set OMNISCAN_BIN")
    return path


def run(*args, **kwargs):
    """Runs an omniscan tool; its stderr is shown when it fails."""
    done = subprocess.run(args, capture_output=True, text=True, **kwargs)
    assert done.returncode == 0, f"{' '.join(map(str, args))} failed:\n{done.stderr}"
    return done


@pytest.fixture(scope="session")
def sim(tmp_path_factory):
    """A true sensor and one scan of the plane scene: frames, manifest, per-frame truth
    ([x, y, z, u, v, laser] of the lit surface), the omni-ridge stripes, omni-triangulate points
    and the omni-merge cloud of those frames."""
    d = tmp_path_factory.mktemp("sim")
    run(tool("omni-sim"), "sensor", "--preset", "paper", "--width", str(WIDTH), "-o", d / "sensor")
    camera, scanner = d / "sensor" / "camera.json", d / "sensor" / "scanner.json"
    scene = os.path.join(REPO, "testdata", "scenes", "plane.json")
    run(tool("omni-sim"), "scan", "--camera", camera, "--scanner", scanner, "--scene", scene,
        "--angles", ANGLES, "--ideal", "--frames", d / "frames", "-o", d / "manifest.jsonl", "--truth", d / "truth.jsonl")
    run(tool("omni-ridge"), "--camera", camera, d / "manifest.jsonl", "-o", d / "stripes.jsonl")
    run(tool("omni-triangulate"), "--camera", camera, "--scanner", scanner, d / "stripes.jsonl",
        "-o", d / "points.jsonl")
    run(tool("omni-merge"), d / "points.jsonl", "-o", d / "cloud.ply")
    with open(d / "truth.jsonl") as f:
        records = [json.loads(line) for line in f if line.strip()]
    truth = [r for r in records if "seq" in r]  # the first line is the file's header
    return {"dir": d, "camera": camera, "scanner": scanner, "truth": truth}
