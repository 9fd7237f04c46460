"""workflow/Snakefile on three tiny simulated scans with `snakemake --cores 2`: the whole batch
runs and measures the scenes; a rerun does nothing; a changed scene reruns only its own scan's
jobs and the summary."""
import json
import os
import shutil
import subprocess
import sys

import pytest
import yaml

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(os.path.dirname(HERE))
SNAKEFILE = os.path.join(REPO, "workflow", "Snakefile")
BIN = os.environ.get("OMNISCAN_BIN", os.path.join(REPO, "target", "debug"))


def snakemake(workdir, config, *args):
    snakemake_exe = os.path.join(os.path.dirname(sys.executable), "snakemake")
    if not os.access(snakemake_exe, os.X_OK):
        pytest.fail(f"{snakemake_exe} is missing: run scripts/deps.sh")
    cmd = [snakemake_exe, "-s", SNAKEFILE, "--configfile", str(config), "--directory", str(workdir),
           "--cores", "2", *args]
    done = subprocess.run(cmd, capture_output=True, text=True)
    assert done.returncode == 0, f"{' '.join(cmd)} failed:\n{done.stdout}\n{done.stderr}"
    return done.stdout + done.stderr


def planned_jobs(plan):
    """The dry run's job stats table: {rule: count, ..., "total": n}."""
    lines = plan.splitlines()
    start = lines.index("Job stats:") + 3  # the title, the column names and the rule line
    jobs = {}
    for line in lines[start:]:
        rule, count = line.split()
        jobs[rule] = int(count)
        if rule == "total":
            return jobs
    raise AssertionError(f"no job stats in:\n{plan}")


def mtimes(root):
    """Modification times of every file under root (outputs of the workflow)."""
    out = {}
    for d, _, files in os.walk(root):
        for name in files:
            path = os.path.join(d, name)
            out[os.path.relpath(path, root)] = os.stat(path).st_mtime_ns
    return out


@pytest.fixture(scope="module")
def batch(tmp_path_factory):
    for name in ("omni-sim", "omni-calib-receiver", "omni-calib-plane", "omni-ridge", "omni-triangulate",
                 "omni-merge", "omni-eval"):
        if not os.access(os.path.join(BIN, name), os.X_OK):
            pytest.fail(f"{BIN}/{name} is missing: build the tools first (cargo build), or set OMNISCAN_BIN")
    work = tmp_path_factory.mktemp("workflow")
    with open(os.path.join(HERE, "config.yaml")) as f:
        config = yaml.safe_load(f)
    config["bin"] = BIN
    config["out"] = str(work / "out")
    config["calibration"]["board"] = os.path.join(REPO, config["calibration"]["board"])
    # The scenes are copied, so that the test can change one.
    (work / "scenes").mkdir()
    for scan in config["scans"].values():
        copy = work / "scenes" / os.path.basename(scan["scene"])
        shutil.copy(os.path.join(REPO, scan["scene"]), copy)
        scan["scene"] = str(copy)
    config_path = work / "config.yaml"
    config_path.write_text(yaml.safe_dump(config))
    snakemake(work, config_path)
    return {"work": work, "out": work / "out", "config": config_path}


def summary(out):
    with open(out / "summary.tsv") as f:
        header, *rows = [line.rstrip("\n").split("\t") for line in f]
    assert header == ["scan", "object", "points", "mean_mm", "std_dev_mm"]
    return {r[0]: {"points": int(r[2]), "mean": float(r[3]), "std": float(r[4])} for r in rows}


def test_the_batch_calibrates_scans_and_measures_every_scene(batch):
    out = batch["out"]
    for f in ("truth/camera.json", "calib/camera.json", "calib/scanner.json", "calib/to_truth.json"):
        assert (out / f).is_file(), f
    table = summary(out)
    assert sorted(table) == ["cylinder", "plane", "sphere"]
    for scan, row in table.items():
        # Errors against the true surfaces (mm) of the calibrated sensor, registered to the truth.
        # Measured: plane 492 points, mean -0.40, σ 0.47; cylinder 75, -0.20, 0.36; sphere 18,
        # -0.10, 0.17 (7 frames of 512 px each).
        assert row["points"] >= 15, (scan, row)
        assert abs(row["mean"]) < 1.0 and row["std"] < 1.5, (scan, row)
        with open(out / "scans" / scan / "eval.json") as f:
            assert json.load(f)["objects"][0]["errors"]["count"] == row["points"]


def test_a_rerun_does_nothing(batch):
    before = mtimes(batch["out"])
    assert "Nothing to be done" in snakemake(batch["work"], batch["config"], "--dry-run")
    snakemake(batch["work"], batch["config"])
    assert mtimes(batch["out"]) == before


def test_a_changed_scene_reruns_only_its_scan(batch):
    out = batch["out"]
    before = mtimes(out)
    config = yaml.safe_load(batch["config"].read_text())
    scene_path = config["scans"]["plane"]["scene"]
    with open(scene_path) as f:
        scene = json.load(f)
    # Move the plane 20 mm farther out along +x (its normal).
    scene["objects"][0]["centre_mm"][0] += 20.0
    with open(scene_path, "w") as f:
        json.dump(scene, f)
    plan = snakemake(batch["work"], batch["config"], "--dry-run")
    jobs = planned_jobs(plan)
    assert jobs == {"scan": 1, "stripes": 1, "reconstruct": 1, "evaluate": 1, "summary": 1, "all": 1, "total": 6}, plan
    snakemake(batch["work"], batch["config"])
    after = mtimes(out)
    changed = {f for f in after if after[f] != before.get(f)}
    assert changed, "nothing was rerun"
    assert all(f.startswith(("scans/plane/", "logs/")) or f == "summary.tsv" for f in changed), sorted(changed)
    assert not any(f.startswith("logs/") and "plane" not in f for f in changed), sorted(changed)
    for scan in ("cylinder", "sphere"):
        assert after[f"scans/{scan}/cloud.ply"] == before[f"scans/{scan}/cloud.ply"]
    # The new scan measures the moved plane as well as the old one measured the first.
    row = summary(out)["plane"]
    assert row["points"] > 200 and abs(row["mean"]) < 1.0 and row["std"] < 1.5, row


def test_a_config_of_another_version_is_refused(tmp_path):
    with open(os.path.join(HERE, "config.yaml")) as f:
        config = yaml.safe_load(f)
    config["version"] = 2
    (tmp_path / "config.yaml").write_text(yaml.safe_dump(config))
    cmd = [os.path.join(os.path.dirname(sys.executable), "snakemake"), "-s", SNAKEFILE, "--configfile",
           str(tmp_path / "config.yaml"), "--directory", str(tmp_path), "--cores", "1", "--dry-run"]
    done = subprocess.run(cmd, capture_output=True, text=True)
    assert done.returncode != 0
    assert "expected format omniscan.workflow version 1" in done.stdout + done.stderr
