#!/usr/bin/env bash
# A real GenICam scan over the GigE Vision stack on `lo` (`make bench`): Aravis's fake camera,
# the `omni-trigger emulate` controller, whose trigger events make `omni-trigger scan --camera`
# fire the camera's software trigger, 1024x1024 Mono8 frames written as PGM and piped into
# omni-ridge. Frames per second through omni-ridge, next to the fake camera's own limits: its
# free-running rate (measured here with arv-camera-test-0.8) and its software trigger, which it
# looks at once per 40 ms (25 Hz), so that triggered it makes at most 25 frames/s, each 0-45 ms
# after its trigger.
# Usage: scripts/bench_fake_camera.sh WORKDIR (created, and removed at the end). Needs
# arv-fake-gv-camera-0.8 and arv-camera-test-0.8 (aravis-tools), omni-trigger built with
# --features aravis and omni-ridge on PATH.
set -uo pipefail
work=${1:?usage: bench_fake_camera.sh WORKDIR}
# The fake camera answers a software trigger at its next 40 ms poll, plus ~5 ms to make and send
# the frame: 0-45 ms late, 24 ms on average (--latency-ms). The pairing accepts a frame within
# +-0.4 of the trigger period of that, so the triggers must come no faster than ~16 Hz; at 20 Hz a
# quarter of the frames fall outside (reported missing, never mis-paired).
RATE_HZ=${RATE_HZ:-16}
mkdir -p "$work"
pids=()
cleanup() {
  for p in "${pids[@]}"; do kill "$p" 2>/dev/null; wait "$p" 2>/dev/null; done
  rm -rf "$work"
}
trap cleanup EXIT

arv-fake-gv-camera-0.8 -i 127.0.0.1 -s BENCH >/dev/null 2>&1 &
pids+=($!)
sleep 0.5
# Free running as fast as it goes (-f 1000 asks for more than it can); the last 3 one-second counts.
free=$(timeout -s INT 6 stdbuf -oL arv-camera-test-0.8 -n 127.0.0.1 -w 1024 -h 1024 -e 1000 -f 1000 2>/dev/null |
  awk '/frames\/s/ { v[n++] = $1 } END { if (n >= 3) printf "%d, %d, %d", v[n-3], v[n-2], v[n-1]; else print "?" }')
echo "Aravis's fake camera free running at 1024x1024 Mono8: $free frames/s (its own limit; its software trigger is looked at every 40 ms: <= 25 frames/s triggered)"

# 4 angles on 12 facets: 48 triggers per revolution, 2 revolutions.
triggers=96
omni-trigger emulate --frames "$work/emulator" --camera-mode blank --max-rate-hz "$RATE_HZ" > "$work/port" 2>/dev/null &
pids+=($!)
for _ in $(seq 50); do [ -s "$work/port" ] && break; sleep 0.1; done
port=$(head -1 "$work/port")
t0=$(date +%s.%N)
omni-trigger scan --port "$port" --camera aravis:127.0.0.1 --trigger software --roi 0,0,1024,1024 \
    --exposure-us 1000 --gain-db 0 --frame-format pgm --frames "$work/camera" \
    --angles 0:30:7.5 --revolutions 2 --latency-ms 24 --max-missing "$triggers" 2>"$work/scan.err" \
  | omni-ridge > "$work/ridges.jsonl"
rc=$?
t1=$(date +%s.%N)
n=$(grep -c '"type":"frame"' "$work/ridges.jsonl")
missing=$(sed -n 's/.*"type":"status".*"frames_missing":\([0-9]*\).*/\1/p' "$work/ridges.jsonl")
# The sustained rate from the first to the last frame's exposure (timestamp_us), without the
# camera's and controller's set-up; the wall time includes it.
grep -o '"timestamp_us":[0-9]*' "$work/ridges.jsonl" | cut -d: -f2 |
  awk -v n="$n" -v m="${missing:-?}" -v a="$t0" -v b="$t1" -v r="$RATE_HZ" -v t="$triggers" '
  NR == 1 { first = $1 } { last = $1 }
  END {
    fps = (n > 1 && last > first) ? (n - 1) / ((last - first) / 1e6) : 0
    printf "omni-trigger scan --camera aravis:127.0.0.1 | omni-ridge, %d triggers at %d Hz: %d frames paired and through omni-ridge (%s missing), %.1f frames/s sustained (%.2f s in all with the set-up); the limit is the fake camera (<= 25 frames/s triggered, 0-45 ms late), not the capture (see the 200 fps figures above)\n", t, r, n, m, fps, b - a }'
[ "$rc" = 0 ] && [ "$n" -gt 0 ] || { echo "bench_fake_camera.sh: the scan failed:" >&2; cat "$work/scan.err" >&2; exit 1; }
