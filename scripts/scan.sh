#!/usr/bin/env bash
# Scan one scene: omni-trigger | omni-ridge | omni-triangulate | omni-merge, and keep every stage.
#
# With real hardware:
#   scripts/scan.sh --camera camera.json --scanner scanner.json --port /dev/ttyACM0 --frames frames/ --out scan/
# (the camera's own software must write the triggered frames into --frames).
# On the virtual sensor (the emulator renders every triggered frame of SCENE through omni-sim):
#   scripts/scan.sh --camera camera.json --scanner scanner.json --emulate scene.json \
#       --true-camera truth/camera.json --true-scanner truth/scanner.json --out scan/
# Writes OUT/manifest.jsonl, OUT/stripes.jsonl, OUT/points.jsonl and OUT/cloud.ply; a scan cut
# short (a failed stage, an interrupted controller) writes no cloud.ply.
# Options: --angles START:STOP:STEP (deg; ANGLES, default 14:29:0.25), --facets LIST (FACETS,
# default 0), --seed N (SEED, the emulator's), --laser-off (a laser-off frame per angle).
# Environment: DENOISE (omni-merge --statistical, default 20,2.0), FRAME_TIMEOUT_MS (default
# 2000), STAGES=stripes (stop after omni-ridge), BIN (the omni-* tools' directory, else PATH).
set -euo pipefail

usage() { sed -n '2,15p' "$0" | sed 's/^# \{0,1\}//'; exit "${1:-2}"; }
camera= scanner= port= scene= true_camera= true_scanner= out= frames=
angles=${ANGLES:-14:29:0.25} facets=${FACETS:-0} seed=${SEED:-0}
denoise=${DENOISE:-20,2.0} laser_off= frame_timeout_ms=${FRAME_TIMEOUT_MS:-2000}
stages=${STAGES:-cloud}  # `stripes`: stop after omni-ridge (calibration scans)
while [ $# -gt 0 ]; do
  case "$1" in
    --camera) camera=$2; shift 2 ;;
    --scanner) scanner=$2; shift 2 ;;
    --port) port=$2; shift 2 ;;
    --frames) frames=$2; shift 2 ;;
    --emulate) scene=$2; shift 2 ;;
    --true-camera) true_camera=$2; shift 2 ;;
    --true-scanner) true_scanner=$2; shift 2 ;;
    --angles) angles=$2; shift 2 ;;
    --facets) facets=$2; shift 2 ;;
    --seed) seed=$2; shift 2 ;;
    --laser-off) laser_off=1; shift ;;
    --out) out=$2; shift 2 ;;
    -h|--help) usage 0 ;;
    *) echo "scan.sh: unknown argument $1" >&2; usage ;;
  esac
done
[ -n "$camera" ] && [ -n "$scanner" ] && [ -n "$out" ] || usage
[ -n "${BIN:-}" ] && PATH="$BIN:$PATH"
[ -n "$port" ] || [ -n "$scene" ] || { echo "scan.sh: give --port or --emulate" >&2; exit 2; }
mkdir -p "$out"
frames=${frames:-$out/frames}
mkdir -p "$frames"

emulator_pid=
cleanup() { [ -n "$emulator_pid" ] && kill "$emulator_pid" 2>/dev/null || true; }
trap cleanup EXIT

if [ -n "$scene" ]; then
  emu_args=(--frames "$frames" --scene "$scene" --seed "$seed" --truth "$out/emulator_truth.jsonl")
  [ -n "$true_camera" ] && emu_args+=(--camera "$true_camera")
  [ -n "$true_scanner" ] && emu_args+=(--scanner "$true_scanner")
  omni-trigger emulate --buffered-camera "${emu_args[@]}" > "$out/emulator.port" 2> "$out/emulator.log" &
  emulator_pid=$!
  # It prints its port once the scene is loaded: allow a loaded machine a minute for that.
  for _ in $(seq 1 600); do
    [ -s "$out/emulator.port" ] && break
    kill -0 "$emulator_pid" 2>/dev/null || break
    sleep 0.1
  done
  port=$(head -n 1 "$out/emulator.port")
  # The emulator's camera buffers frames (renders slower than it is triggered): wait for them.
  frame_timeout_ms=600000
  [ -n "$port" ] || { echo "scan.sh: the emulator did not start (see $out/emulator.log)" >&2; exit 1; }
fi

trigger() {
  omni-trigger scan --port "$port" --frames "$frames" --angles "$angles" --facets "$facets" --revolutions 1 \
    --frame-timeout-ms "$frame_timeout_ms" ${laser_off:+--laser-off} | tee "$out/manifest.jsonl"
}
if [ "$stages" = stripes ]; then
  trigger | omni-ridge --camera "$camera" -o "$out/stripes.jsonl"
else
  trigger \
    | omni-ridge --camera "$camera" | tee "$out/stripes.jsonl" \
    | omni-triangulate --strict --camera "$camera" --scanner "$scanner" | tee "$out/points.jsonl" \
    | omni-merge - --strict --statistical "$denoise" -o "$out/cloud.ply"
fi
echo "scan.sh: $(grep -c '"type":"frame"' "$out/manifest.jsonl" || true) frames -> $out" >&2
