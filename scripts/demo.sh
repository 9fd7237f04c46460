#!/usr/bin/env bash
# The main job on the virtual sensor (README: `make demo`):
#  1. create a realistic, imperfect virtual sensor (the truth the pipeline must recover);
#  2. calibrate it as a user would calibrate hardware (scripts/calibrate.sh);
#  3. scan the paper's test objects through omni-trigger (emulator) | omni-ridge |
#     omni-triangulate | omni-merge (scripts/scan.sh), each frame with a laser-off frame (the
#     room is lit: without it a silhouette's ambient edge cuts the last px of curved stripes);
#  4. evaluate with omni-eval and print one table: the paper's numbers, ours with the calibrated
#     sensor, ours with the true sensor files (the floor set by noise alone);
#  5. leave PLY files and a PNG picture of each cloud in $OUT.
# Environment: OUT (default out/demo), BIN (directory of the omni-* binaries, default
# target/release), DEMO_SIZE=small for the reduced run used by the CI test.
set -euo pipefail
case "${1:-}" in
  "") ;;
  -h|--help) sed -n '2,12p' "$0" | sed 's/^# \{0,1\}//'; exit 0 ;;
  *) echo "demo.sh: no arguments (the environment sets it up: see --help), got $1" >&2; exit 2 ;;
esac
here=$(cd "$(dirname "$0")/.." && pwd)
OUT=${OUT:-out/demo}
BIN=${BIN:-$here/target/release}
export PATH="$BIN:$PATH"
size=${DEMO_SIZE:-full}
if [ "$size" = small ]; then
  boards=20; rig_angles=15:23:0.5; scan_angles=15:29:1; objects="plane cylinder sphere"
else
  boards=20; rig_angles=14:28:0.5; scan_angles=14:29:0.25; objects="plane cylinder sphere cone_pyramid"
fi
mkdir -p "$OUT"
OUT=$(cd "$OUT" && pwd)
log() { echo "demo: $*" >&2; }
start=$(date +%s)

log "1/5 virtual sensor with build errors -> $OUT/truth"
omni-sim sensor --preset paper --camera-offset 0.2,-0.1,0.5 --principal-point-offset 2.5,-1.5 \
  --facet-errors 0.03 --encoder-offset 0.15 --seed 7 -o "$OUT/truth"
board="$here/testdata/boards/board_9x6.json"

log "2/5 calibration: $boards board images, rig pose image, rig scan through the emulator"
omni-sim boards --camera "$OUT/truth/camera.json" --board "$board" --count "$boards" --seed 1 --out "$OUT/capture/boards" >/dev/null
omni-sim rig --camera "$OUT/truth/camera.json" --scanner "$OUT/truth/scanner.json" --board "$board" \
  --angles 15 --out "$OUT/capture/rig" >/dev/null
"$here/scripts/calibrate.sh" --board "$board" --boards "$OUT/capture/boards" --rig "$OUT/capture/rig/rig.json" \
  --pose-image "$OUT/capture/rig/pose.png" --emulate "$OUT/capture/rig/scene.json" \
  --true-camera "$OUT/truth/camera.json" --true-scanner "$OUT/truth/scanner.json" \
  --angles "$rig_angles" --out "$OUT/calib"
omni-eval align --scanner "$OUT/calib/scanner.json" --reference-poses "$OUT/capture/rig/board_poses.json" \
  --rig "$OUT/capture/rig/rig.json" -o "$OUT/calib/to_truth.json"

log "3/5 scans: $objects"
for obj in $objects; do
  scene="$here/testdata/scenes/$obj.json"
  ANGLES=$scan_angles "$here/scripts/scan.sh" --camera "$OUT/calib/camera.json" --scanner "$OUT/calib/scanner.json" \
    --emulate "$scene" --true-camera "$OUT/truth/camera.json" --true-scanner "$OUT/truth/scanner.json" \
    --laser-off --out "$OUT/$obj"
  # The same stripes reconstructed with the true sensor files: the floor set by noise alone.
  omni-triangulate --camera "$OUT/truth/camera.json" --scanner "$OUT/truth/scanner.json" "$OUT/$obj/stripes.jsonl" \
    | omni-merge - --statistical 20,2.0 -o "$OUT/$obj/cloud_true_sensor.ply"
  omni-eval render "$OUT/$obj/cloud.ply" -o "$OUT/$obj/cloud.png"
done

log "4/5 evaluation"
python3 "$here/scripts/demo_table.py" "$OUT" $objects | tee "$OUT/table.txt"
# Where the table names a speckle reducer for the plane, the plane is scanned again through it
# (the true camera's optics changed to its patterns and F-number; the calibration kept), so
# that the named optics are a rendered measurement, not only the budget's prediction.
reducer=$(python3 "$here/scripts/demo_table.py" --reducer "$OUT")
if [ -n "$reducer" ]; then
  read -r patterns f_number <<<"$reducer"
  log "4/5 the plane through the speckle reducer: $patterns patterns, F/$f_number"
  mkdir -p "$OUT/plane_reducer"
  python3 "$here/scripts/demo_table.py" --optics "$OUT/truth/camera.json" "$patterns" "$f_number" \
    > "$OUT/plane_reducer/true_camera.json"
  ANGLES=$scan_angles "$here/scripts/scan.sh" --camera "$OUT/calib/camera.json" --scanner "$OUT/calib/scanner.json" \
    --emulate "$here/testdata/scenes/plane.json" --true-camera "$OUT/plane_reducer/true_camera.json" \
    --true-scanner "$OUT/truth/scanner.json" --laser-off --out "$OUT/plane_reducer"
  python3 "$here/scripts/demo_table.py" --reducer-measured "$OUT" | tee -a "$OUT/table.txt"
fi

log "5/5 done in $(( $(date +%s) - start )) s: clouds, pictures and the table are in $OUT"
