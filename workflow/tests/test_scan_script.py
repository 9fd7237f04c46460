"""scripts/scan.sh, the scripted scan (omni-trigger | omni-ridge | omni-triangulate | omni-merge),
when a stage fails or the scan is cut short: the script fails, naming the cause, and writes no
cloud.ply (a partial cloud would pass for a whole scan). The controller is a stand-in that
replays a rendered scan's manifest."""
import os
import subprocess

import pytest

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(os.path.dirname(HERE))
SCAN_SH = os.path.join(REPO, "scripts", "scan.sh")
BIN = os.environ.get("OMNISCAN_BIN", os.path.join(REPO, "target", "debug"))
PLANE = os.path.join(REPO, "testdata", "scenes", "plane.json")


@pytest.fixture(scope="module")
def scan(tmp_path_factory):
    """A small sensor and a 4-frame scan of the plane (frames and manifest)."""
    work = tmp_path_factory.mktemp("scan_sh")
    sim = os.path.join(BIN, "omni-sim")
    subprocess.run([sim, "sensor", "--preset", "paper", "--width", "256", "-o", work / "sensor"], check=True,
                   capture_output=True)
    subprocess.run([sim, "scan", "--camera", work / "sensor/camera.json", "--scanner", work / "sensor/scanner.json",
                    "--scene", PLANE, "--angles", "18:21:1", "--ideal", "--frames", work / "frames",
                    "-o", work / "manifest.jsonl"], check=True, capture_output=True)
    return work


def run_scan(work, manifest_text, name):
    """scan.sh with a stand-in omni-trigger that prints `manifest_text`."""
    fake = work / f"fake_{name}"
    fake.mkdir()
    (fake / "manifest.jsonl").write_text(manifest_text)
    trigger = fake / "omni-trigger"
    trigger.write_text(f"#!/bin/sh\ncat {fake / 'manifest.jsonl'}\n")
    trigger.chmod(0o755)
    out = work / f"out_{name}"
    env = dict(os.environ, PATH=f"{fake}:{BIN}:{os.environ['PATH']}")
    env.pop("BIN", None)
    done = subprocess.run(["bash", SCAN_SH, "--camera", work / "sensor/camera.json", "--scanner",
                           work / "sensor/scanner.json", "--port", "/dev/null", "--frames", work / "frames",
                           "--out", out], env=env, capture_output=True, text=True)
    return done, out


def test_a_whole_scan_makes_its_cloud(scan):
    done, out = run_scan(scan, (scan / "manifest.jsonl").read_text(), "whole")
    assert done.returncode == 0, done.stderr
    assert (out / "cloud.ply").stat().st_size > 1000


def test_a_corrupt_frame_fails_the_scan_without_a_cloud(scan):
    frame = scan / "frames" / "frame_000001.png"
    whole = frame.read_bytes()
    try:
        frame.write_bytes(whole[:200])
        done, out = run_scan(scan, (scan / "manifest.jsonl").read_text(), "corrupt")
    finally:
        frame.write_bytes(whole)
    assert done.returncode != 0
    assert "frame_000001.png: truncated or corrupt image" in done.stderr, done.stderr
    assert not (out / "cloud.ply").exists()


def test_an_interrupted_scan_leaves_no_cloud(scan):
    text = (scan / "manifest.jsonl").read_text().replace('"complete":true', '"complete":false')
    assert '"complete":false' in text
    done, out = run_scan(scan, text, "interrupted")
    assert done.returncode != 0
    assert "marked incomplete" in done.stderr and "--strict" in done.stderr, done.stderr
    assert not (out / "cloud.ply").exists()
