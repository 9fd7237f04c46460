#!/usr/bin/env python3
"""The live path under an emulated 1 MP camera at 200 fps (`make bench`; issue "Live for robots").

An emulated camera writes realistic room frames (1024 x 1024 PGM, rendered once by omni-sim)
into a frames directory at the camera's rate and emits each frame's manifest record as
omni-trigger would; the live chain measures and publishes them:

    camera | omni-ridge --camera --binary | omni-triangulate --binary | omni-live --ros2

(`--json` runs the same chain with JSON Lines streams, for comparison.)

with a ROS-free DDS subscriber (Cyclone) taking every cloud. Everything runs in a network
namespace of its own (`unshare --net`, loopback only; needs root). Prints:
- latency from a sweep's last frame being written by the camera to the end of that sweep's
  publication: p50, p99, max (ms);
- CPU of the chain (omni-ridge + omni-triangulate + omni-live) and of the camera emulation, as a
  share of the 2 cores over the run;
- resident memory of each process in the first and the last tenth of the run, its peak, and its
  mean in each tenth (flat or still growing), and the frames directory's size (disk flat: frames deleted once measured).

Usage: scripts/bench_live.py [--bin DIR] [--seconds S] [--fps F] [--json]   (inside: --inner ...)
"""

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
ANGLES = "14:29:0.25"  # 60 frames per sweep, as the demo's room scan
ROOM = {"format": "omniscan.scene", "version": 1,
        "objects": [{"name": "room", "albedo": 0.8, "type": "room", "centre_mm": [0, 0, 0],
                     "size_mm": [1600, 1600, 1000]}]}


def render(bin_dir: Path, work: Path) -> list:
    sim = str(bin_dir / "omni-sim")
    subprocess.run([sim, "sensor", "--preset", "paper", "-o", work / "sensor"], check=True, capture_output=True)
    (work / "room.json").write_text(json.dumps(ROOM))
    subprocess.run([sim, "scan", "--camera", work / "sensor/camera.json", "--scanner", work / "sensor/scanner.json",
                    "--scene", work / "room.json", "--angles", ANGLES, "--format", "pgm", "--frames", work / "room",
                    "-o", work / "room.jsonl"], check=True, capture_output=True)
    return [json.loads(line) for line in (work / "room.jsonl").read_text().splitlines()
            if json.loads(line)["type"] == "frame"]


def proc_cpu_s(pid: int) -> float:
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def proc_rss_kib(pid: int) -> int:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1])
    return 0


def dir_bytes(d: Path) -> int:
    return sum(f.stat().st_size for f in d.iterdir() if f.is_file())


def inner(args) -> int:
    bin_dir, work = Path(args.bin), Path(args.work)
    frames = render(bin_dir, work)
    images = [(work / "room" / f["path"]).read_bytes() for f in frames]
    live_dir = work / "live"
    live_dir.mkdir()
    sub = subprocess.Popen([sys.executable, str(ROOT / "bin/omni-live/tests/ros2_peer.py"), "--subscribe-only",
                            "/omniscan", "0"], stdout=subprocess.PIPE)
    sub.stdout.readline()
    cam = ["--camera", str(work / "sensor/camera.json")]
    binary = [] if args.json else ["--binary"]
    ridge = subprocess.Popen([str(bin_dir / "omni-ridge"), *cam, *binary, "-"], stdin=subprocess.PIPE,
                             stdout=subprocess.PIPE)
    tri = subprocess.Popen([str(bin_dir / "omni-triangulate"), *cam, *binary,
                            "--scanner", str(work / "sensor/scanner.json")],
                           stdin=ridge.stdout, stdout=subprocess.PIPE)
    live = subprocess.Popen([str(bin_dir / "omni-live"), "--ros2", "--queue", "2"],
                            stdin=tri.stdout, stdout=subprocess.PIPE)
    reports = []
    reader = threading.Thread(target=lambda: reports.extend(json.loads(x) for x in live.stdout))
    reader.start()
    pids = {"omni-ridge": ridge.pid, "omni-triangulate": tri.pid, "omni-live": live.pid}
    header = {"type": "header", "format": "omniscan.stream", "version": 1, "producers": ["bench_live.py camera"],
              "frames_dir": str(live_dir), "angles": ANGLES, "live": True}
    ridge.stdin.write((json.dumps(header) + "\n").encode())
    period = 1.0 / args.fps
    n_total = int(args.seconds * args.fps)
    written_us: dict = {}
    samples = []
    cpu0 = {k: proc_cpu_s(p) for k, p in pids.items()}
    self0, t0 = time.process_time(), time.monotonic()
    next_sample = t0
    for seq in range(n_total):
        due = t0 + seq * period
        now = time.monotonic()
        if due > now:
            time.sleep(due - now)
        i = seq % len(frames)
        name = f"f{seq:08d}.pgm"
        (live_dir / name).write_bytes(images[i])
        written_us[seq] = time.time_ns() // 1000
        sweep = seq // len(frames)
        rec = dict(frames[i], seq=seq, path=name, revolution=sweep // 12, facet=sweep % 12,
                   timestamp_us=written_us[seq])
        ridge.stdin.write((json.dumps(rec) + "\n").encode())
        ridge.stdin.flush()
        if time.monotonic() >= next_sample:
            samples.append({"t": time.monotonic() - t0, "disk": dir_bytes(live_dir),
                            **{k: proc_rss_kib(p) for k, p in pids.items()}})
            next_sample += 1.0
    wall = time.monotonic() - t0
    cpu = {k: proc_cpu_s(p) - cpu0[k] for k, p in pids.items()}
    camera_cpu = time.process_time() - self0
    late = max(0.0, time.monotonic() - (t0 + n_total * period))
    ridge.stdin.write((json.dumps({"type": "status", "frames": n_total, "frames_missing": 0, "complete": True,
                                   "errors": []}) + "\n").encode())
    ridge.stdin.close()
    for p in (ridge, tri, live):
        p.wait(timeout=120)
    reader.join()
    sub.kill()
    per_sweep = len(frames)
    lat = sorted((r["published_unix_us"] - written_us[(r["revolution"] * 12 + r["facet"]) * per_sweep + per_sweep - 1])
                 / 1000.0 for r in reports if r.get("type") == "sweep" and r["complete"])
    status = reports[-1]
    tenth = max(1, len(samples) // 10)
    first, last = samples[:tenth], samples[-tenth:]
    mean = lambda rows, k: sum(r[k] for r in rows) / len(rows)  # noqa: E731
    print(json.dumps({
        "streams": "json" if args.json else "binary", "fps": args.fps, "seconds": round(wall, 1), "frames": n_total, "camera_behind_s": round(late, 3),
        "sweeps_published": len(lat), "status": status,
        "latency_ms": {"p50": lat[len(lat) // 2], "p99": lat[min(len(lat) - 1, int(0.99 * len(lat)))],
                       "max": lat[-1]} if lat else None,
        "cpu_share_of_2_cores": {**{k: round(v / wall / 2, 3) for k, v in cpu.items()},
                                 "chain": round(sum(cpu.values()) / wall / 2, 3),
                                 "camera_emulation": round(camera_cpu / wall / 2, 3)},
        "rss_mib_first_last_max": {k: [round(mean(first, k) / 1024, 1), round(mean(last, k) / 1024, 1),
                                       round(max(s[k] for s in samples) / 1024, 1)] for k in pids},
        "rss_mib_by_tenth": {k: [round(mean(samples[i * tenth:(i + 1) * tenth], k) / 1024, 1)
                                 for i in range(len(samples) // tenth)] for k in pids},
        "frames_dir_mib_first_last_max": [round(mean(first, "disk") / 2**20, 1), round(mean(last, "disk") / 2**20, 1),
                                          round(max(s["disk"] for s in samples) / 2**20, 1)],
    }))
    return 0


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--bin", default=str(ROOT / "target/release"))
    ap.add_argument("--seconds", type=float, default=60.0)
    ap.add_argument("--fps", type=float, default=200.0)
    ap.add_argument("--json", action="store_true", help="JSON Lines streams between the tools (default: binary)")
    ap.add_argument("--inner", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--work", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.inner:
        return inner(args)
    work = Path(tempfile.mkdtemp(prefix="omni-live-bench-", dir="/dev/shm" if Path("/dev/shm").is_dir() else None))
    try:
        script = ("ip link set lo up && ip link set lo multicast on && ip route add 224.0.0.0/4 dev lo && "
                  f"exec {sys.executable} {Path(__file__).resolve()} --inner --bin {args.bin} --work {work} "
                  f"--seconds {args.seconds} --fps {args.fps}" + (" --json" if args.json else ""))
        p = subprocess.run(["unshare", "--net", "sh", "-c", script], capture_output=True, text=True)
        if p.returncode != 0:
            sys.exit(f"bench_live.py: {p.stderr.strip()[-2000:]}")
        result = json.loads(p.stdout.strip().splitlines()[-1])
        print("{\n" + ",\n".join(f" {json.dumps(k)}: {json.dumps(v)}" for k, v in result.items()) + "\n}")
    finally:
        shutil.rmtree(work, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
