"""omni-ridge on the real hand-held laser photographs (../shared/data/real-laser-handheld),
judged by geometry (scripts/real_laser.py): the stripe on the flat board, undistorted by an
independent OpenCV calibration, is a (gently bent) line. Targets of the issue "omni-ridge finds
real laser stripes", against a column-centroid reference on the same frames; the figures
measured when these were set are in docs/DECISIONS.md ("Real laser stripes").
"""

import os
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[3]
sys.path.insert(0, str(ROOT / "scripts"))
import real_laser  # noqa: E402

BINARY = Path(os.environ.get("OMNI_RIDGE", ROOT / "target" / "debug" / "omni-ridge"))


@pytest.fixture(scope="module")
def laser_red():
    if not real_laser.DATA.is_dir():
        pytest.fail(f"{real_laser.DATA} is missing: the shared data sits beside the clone")
    return real_laser.evaluate(BINARY, ["--laser", "red"])


def test_the_board_is_found_and_the_camera_calibrated(laser_red):
    cam, results = laser_red
    # OpenCV's own calibration of the 19 board frames: the undistortion behind the lines.
    assert cam.rms < 0.5, cam.rms
    # Every stripe frame is judged: twelve on OpenCV's boards, the five close-ups (saturated
    # cores, boards cut at the frame's edge) on omniscan's corners.
    assert sum(r.board and r.length_px > 0 for r in results) == 17, real_laser.table(cam, results)
    assert sum(r.board_by_omniscan for r in results) == 5, real_laser.table(cam, results)


def test_coverage_is_at_least_the_references_on_every_frame(laser_red):
    cam, results = laser_red
    report = real_laser.table(cam, results)
    for r in results:
        if r.board and r.length_px > 0:
            # Measured: 69-100 % per frame against the reference's 27-92 %.
            assert r.ridge.coverage >= r.reference.coverage, f"{r.name}\n{report}"
            assert r.ridge.coverage >= 0.6, f"{r.name}\n{report}"
    total = real_laser.totals(results, "ridge")
    # Measured: 94 % of 13.3k px of stripe against the reference's 48 %.
    assert total.coverage >= 0.9, report
    reaching = [r for r in results if r.board and r.reference.coverage >= 0.9]
    if reaching:
        covered = sum(r.ridge.coverage * r.length_px for r in reaching) / sum(r.length_px for r in reaching)
        assert covered >= 0.9, report


def test_false_points_apart_from_reflections_stay_under_one_percent(laser_red):
    cam, results = laser_red
    total = real_laser.totals(results, "ridge")
    # Measured: 5.0 % off the line, 4.7 % of them on reflections of the stripe (laser light
    # 15 px or more off it, a stripe like any other): 0.3 % false on the board's texture.
    assert total.false_share - total.ghost_share <= 0.01, real_laser.table(cam, results)


@pytest.fixture(scope="module")
def one_per_column():
    return real_laser.evaluate(BINARY, ["--laser", "red", "--one-stripe-per", "column"])


def test_one_stripe_per_column_drops_the_reflections_and_keeps_the_stripe(laser_red, one_per_column):
    """The hand-held sensor's laser lights one point per column: with --one-stripe-per column
    the false points, reflections included, stay under 1 %, and the stripe is covered as before."""
    cam, results = one_per_column
    report = real_laser.table(cam, results)
    total = real_laser.totals(results, "ridge")
    # Measured: 0.5 % off the line in all (5.0 % without), of which 0.4 % reflections crossing
    # columns where the stripe itself is dim print (im14) or missing (im11).
    assert total.false_share <= 0.01, report
    for before, after in zip(laser_red[1], results):
        if before.board and before.length_px > 0:
            # Measured: the same on every frame within 0.1 % (the line is refitted to the points).
            assert after.ridge.coverage >= before.ridge.coverage - 0.005, f"{after.name}\n{report}"


def test_rms_about_the_line_is_no_worse_than_the_references(laser_red):
    cam, results = laser_red
    report = real_laser.table(cam, results)
    for r in results:
        if r.board and r.length_px > 0 and np.isfinite(r.reference.rms):
            # Measured: 0.12-0.66 px against 0.52-1.16 px.
            assert r.ridge.rms <= r.reference.rms, f"{r.name}\n{report}"


def test_luma_reading_finds_the_texture_the_laser_contrast_ignores():
    """The reason for --laser: read as luma, the lit board's checks give false points."""
    cam, results = real_laser.evaluate(BINARY, [], names=["im12.png", "im13.png"])
    luma = real_laser.totals(results, "ridge")
    # Measured: 20 % of the points > 3 px off the stripe (on the checks' corners and edges).
    assert luma.false_share - luma.ghost_share > 0.05, real_laser.table(cam, results)
