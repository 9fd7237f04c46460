"""workflow/Snakefile on three tiny simulated scans with `snakemake --cores 2`: the whole batch
runs and measures the scenes; a rerun does nothing; a changed scene reruns only its own scan's
jobs and the summary. Then the same batch through Slurm with workflow/profiles/slurm, on a
one-node cluster (scripts/slurm_cluster.sh, needs root): the same clouds and summary, byte for
byte; a failing job's log shown; a cancelled job failing the workflow."""
import glob
import json
import os
import re
import shutil
import subprocess
import sys
import time

import pytest
import yaml

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(os.path.dirname(HERE))
SNAKEFILE = os.path.join(REPO, "workflow", "Snakefile")
BIN = os.environ.get("OMNISCAN_BIN", os.path.join(REPO, "target", "debug"))
SLURM_PROFILE = os.path.join(REPO, "workflow", "profiles", "slurm")
SLURM_CLUSTER = os.path.join(REPO, "scripts", "slurm_cluster.sh")
# What the Slurm run must reproduce byte for byte (relative to the batch's `out`).
COMPARED = ("summary.tsv", "scans/*/cloud.ply")


def snakemake_cmd(workdir, config, *args):
    snakemake_exe = os.path.join(os.path.dirname(sys.executable), "snakemake")
    if not os.access(snakemake_exe, os.X_OK):
        pytest.fail(f"{snakemake_exe} is missing: run scripts/deps.sh")
    return [snakemake_exe, "-s", SNAKEFILE, "--configfile", str(config), "--directory", str(workdir), *args]


def snakemake(workdir, config, *args):
    cmd = snakemake_cmd(workdir, config, "--cores", "2", *args)
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


def write_batch(work, change=None, out="out", bin_dir=BIN):
    """The test batch in `work` (outputs in work/`out`, its own copy of the scenes, so that a test
    can change one; the tools in `bin_dir`); `change(config)` edits it first. Returns the
    config's path."""
    with open(os.path.join(HERE, "config.yaml")) as f:
        config = yaml.safe_load(f)
    config["bin"] = bin_dir
    config["out"] = str(work / out)
    config["calibration"]["board"] = os.path.join(REPO, config["calibration"]["board"])
    (work / "scenes").mkdir()
    for scan in config["scans"].values():
        copy = work / "scenes" / os.path.basename(scan["scene"])
        shutil.copy(os.path.join(REPO, scan["scene"]), copy)
        scan["scene"] = str(copy)
    if change:
        change(config)
    config_path = work / "config.yaml"
    config_path.write_text(yaml.safe_dump(config))
    return config_path


def compared_outputs(out):
    files = {os.path.relpath(p, out): p for pattern in COMPARED for p in glob.glob(os.path.join(out, pattern))}
    assert "summary.tsv" in files and len(files) == 4, sorted(files)  # the summary, three clouds
    return {rel: open(path, "rb").read() for rel, path in sorted(files.items())}


TOOLS = ("omni-sim", "omni-calib-receiver", "omni-calib-plane", "omni-ridge", "omni-triangulate", "omni-merge",
         "omni-eval")


@pytest.fixture(scope="module")
def batch(tmp_path_factory):
    for name in TOOLS:
        if not os.access(os.path.join(BIN, name), os.X_OK):
            pytest.fail(f"{BIN}/{name} is missing: build the tools first (cargo build), or set OMNISCAN_BIN")
    work = tmp_path_factory.mktemp("workflow")
    # The tools through links of their own, which a test replaces by a "rebuilt" tool; an output
    # directory with a space in its name, which every rule's command must quote.
    links = work / "bin"
    links.mkdir()
    for name in TOOLS:
        os.symlink(os.path.join(BIN, name), links / name)
    out = work / "out dir"
    config_path = write_batch(work, out=out.name, bin_dir=str(links))
    snakemake(work, config_path)
    # The outputs as the local run made them, before a test changes a scene.
    return {"work": work, "out": out, "bin": links, "config": config_path, "outputs": compared_outputs(out)}


def summary(out):
    with open(out / "summary.tsv") as f:
        header, *rows = [line.rstrip("\n").split("\t") for line in f]
    assert header == ["scan", "object", "points", "mean_mm", "std_dev_mm"]
    return {r[0]: {"points": int(r[2]), "mean": float(r[3]), "std": float(r[4])} for r in rows}


def test_the_batch_calibrates_scans_and_measures_every_scene(batch):
    out = batch["out"]
    for f in ("truth/camera.json", "calib/camera.json", "calib/scanner.json", "calib/to_truth.json"):
        assert (out / f).is_file(), f
    # The calibration reports (the tools write them to stderr).
    assert "corners" in (out / "calib/receiver.txt").read_text()
    assert "model residual RMS" in (out / "calib/planes.txt").read_text()
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


def test_a_rebuilt_tool_reruns_what_it_made(batch):
    """A tool is an input of the jobs that run it: after a rebuild (here omni-merge replaced by a
    wrapper, other bytes), only the clouds and what reads them are planned again."""
    link = batch["bin"] / "omni-merge"
    os.unlink(link)
    link.write_text(f'#!/bin/sh\nexec {os.path.join(BIN, "omni-merge")} "$@"\n')
    link.chmod(0o755)
    try:
        jobs = planned_jobs(snakemake(batch["work"], batch["config"], "--dry-run"))
    finally:
        link.unlink()
        os.symlink(os.path.join(BIN, "omni-merge"), link)
    assert jobs == {"reconstruct": 3, "evaluate": 3, "summary": 1, "all": 1, "total": 8}, jobs


def test_a_misspelt_or_missing_config_key_is_named(tmp_path):
    for change, says in [
        (lambda c: c["scans"]["plane"].update(sed=3), "scan plane has unknown keys sed"),
        (lambda c: c["scans"]["plane"].pop("angles"), "scan plane lacks angles"),
        (lambda c: c.pop("denoise"), "the config lacks denoise"),
    ]:
        work = tmp_path / str(len(list(tmp_path.iterdir())))
        work.mkdir()
        cmd = snakemake_cmd(work, write_batch(work, change), "--cores", "1", "--dry-run")
        done = subprocess.run(cmd, capture_output=True, text=True)
        assert done.returncode != 0 and says in done.stdout + done.stderr, done.stdout + done.stderr


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


# The Slurm leg: a one-node cluster on this machine for the module's Slurm tests.
@pytest.fixture(scope="module")
def slurm(tmp_path_factory):
    """The cluster's environment (SLURM_CONF set); torn down after the module's last test, and
    checked: no daemon left, no job state carried into the next run."""
    if os.geteuid() != 0:
        if os.environ.get("CI"):
            pytest.fail("the Slurm tests need root (slurmd starts every job as its user)")
        pytest.skip("the Slurm tests need root (slurmd starts every job as its user); CI runs them")
    scratch = tmp_path_factory.mktemp("slurm")
    log_path = scratch / "slurm_cluster.log"
    log = open(log_path, "w")
    # The script keeps the cluster up until its stdin closes: it goes down with this process.
    proc = subprocess.Popen([SLURM_CLUSTER, "--dir", str(scratch / "cluster")], stdin=subprocess.PIPE,
                            stdout=subprocess.PIPE, stderr=log, text=True)
    ready = proc.stdout.readline()
    match = re.match(r"slurm_cluster: ready SLURM_CONF=(\S+) pids=(\S+)$", ready.strip())
    if not match:
        proc.stdin.close()
        proc.wait(timeout=120)
        pytest.fail(f"{SLURM_CLUSTER} did not come up (exit {proc.returncode}):\n{log_path.read_text()}")
    pids = dict(p.split(":") for p in match[2].split(","))
    env = dict(os.environ, SLURM_CONF=match[1])
    # A fresh cluster: no job of an earlier run in its queue, finished or not.
    queue = subprocess.run(["squeue", "-h", "-t", "all", "-o", "%i %j %T"], env=env, capture_output=True,
                           text=True, check=True)
    assert queue.stdout == "", f"a new cluster with jobs in its queue:\n{queue.stdout}"
    yield env
    proc.stdin.close()
    try:
        proc.wait(timeout=120)
    except subprocess.TimeoutExpired:
        proc.terminate()
        proc.wait(timeout=60)
        pytest.fail(f"{SLURM_CLUSTER} did not stop within 120 s of its stdin closing:\n{log_path.read_text()}")
    assert proc.returncode == 0, f"{SLURM_CLUSTER} exited {proc.returncode}:\n{log_path.read_text()}"
    for name, pid in pids.items():
        assert not os.path.exists(f"/proc/{pid}"), f"{name} (pid {pid}) is still there after the teardown"
    assert not (scratch / "cluster").exists(), "the cluster's scratch directory was left behind"
    assert not os.path.lexists("/run/slurm/conf"), "slurmd's config cache link was left behind"


def slurm_snakemake_cmd(work, config):
    """`snakemake --executor slurm` with the repository's profile, unchanged."""
    return snakemake_cmd(work, config, "--workflow-profile", SLURM_PROFILE)


def slurm_snakemake(env, work, config, timeout=600):
    done = subprocess.run(slurm_snakemake_cmd(work, config), capture_output=True, text=True, env=env, cwd=work,
                          timeout=timeout)
    return done.returncode, done.stdout + done.stderr


@pytest.fixture(scope="module")
def slurm_batch(slurm, tmp_path_factory):
    """The test batch through Slurm, started in the background: most of its time is waiting for
    the plugin's status checks, and the tests of a failing and a cancelled job run meanwhile."""
    work = tmp_path_factory.mktemp("slurm_batch")
    log = open(work / "snakemake.log", "w+")
    proc = subprocess.Popen(slurm_snakemake_cmd(work, write_batch(work)), stdout=log, stderr=subprocess.STDOUT,
                            env=slurm, cwd=work)
    yield {"proc": proc, "work": work, "log": work / "snakemake.log"}
    if proc.poll() is None:
        proc.kill()
        proc.wait()
    log.close()


def test_a_failing_slurm_job_shows_its_log(slurm, slurm_batch, tmp_path):
    def bad_sensor(config):
        config["sensor"]["width"] = 0
    status, log = slurm_snakemake(slurm, tmp_path, write_batch(tmp_path, bad_sensor))
    assert status != 0, log
    assert "Error in rule sensor" in log, log
    # The tool's own message, from the job's log file.
    assert "omni-sim: error: --width must be in 16..=8192, got 0" in log, log


def test_a_cancelled_slurm_job_fails_the_workflow_with_its_name(slurm, slurm_batch, tmp_path):
    cmd = slurm_snakemake_cmd(tmp_path, write_batch(tmp_path))
    with open(tmp_path / "snakemake.log", "w+") as out:
        proc = subprocess.Popen(cmd, stdout=out, stderr=subprocess.STDOUT, env=slurm, cwd=tmp_path)
        try:
            # This run's first job (the sensor; the job's directory is the run's) as soon as Slurm
            # has it: it starts Snakemake twice before its tool, seconds in which scancel finds it
            # queued or running.
            deadline = time.monotonic() + 120
            job = None
            while job is None and proc.poll() is None and time.monotonic() < deadline:
                queue = subprocess.run(["squeue", "-h", "-t", "pending,running", "-o", "%i %Z"], env=slurm,
                                       capture_output=True, text=True, check=True).stdout
                job = next((j for j, d in (line.split(" ", 1) for line in queue.splitlines())
                            if d == str(tmp_path)), None)
                time.sleep(0.05)
            assert job, f"no job of this run queued:\n{(tmp_path / 'snakemake.log').read_text()}"
            subprocess.run(["scancel", job], env=slurm, check=True)
            status = proc.wait(timeout=300)
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait()
        log = (tmp_path / "snakemake.log").read_text()
    assert status != 0, log
    assert f"SLURM-job '{job}' failed, SLURM status is: 'CANCELLED'" in log, log
    assert "Error in rule sensor" in log, log


def test_the_batch_through_slurm_makes_the_same_outputs(batch, slurm, slurm_batch):
    try:
        status = slurm_batch["proc"].wait(timeout=600)
    except subprocess.TimeoutExpired:
        pytest.fail(f"the Slurm run took over 10 min:\n{slurm_batch['log'].read_text()}")
    log = slurm_batch["log"].read_text()
    assert status == 0, log
    # Every job went through Slurm and completed there (the summary and `all` run locally).
    submitted = set(re.findall(r"has been submitted with SLURM jobid (\d+)", log))
    assert len(submitted) == 19, log
    queue = subprocess.run(["squeue", "-h", "-t", "all", "-o", "%i %T"], env=slurm, capture_output=True,
                           text=True, check=True)
    states = dict(line.split() for line in queue.stdout.splitlines())
    assert {states.get(job) for job in submitted} == {"COMPLETED"}, queue.stdout
    outputs = compared_outputs(slurm_batch["work"] / "out")
    for rel, local in batch["outputs"].items():
        assert outputs[rel] == local, f"{rel} differs between the local and the Slurm run"
