#!/usr/bin/env bash
# Calibrate the sensor: the receiver from checkerboard images, then the light planes from the
# two-perpendicular-boards rig scanned over the mirror angles.
#
#   scripts/calibrate.sh --board board.json --boards boards/ --rig rig.json --pose-image pose.png \
#       (--port /dev/ttyACM0 --frames frames/ | --emulate rig_scene.json [--true-camera C --true-scanner S]) \
#       [--rim-image lit.png] --out calib/
#
# boards/ holds the checkerboard images (any poses around the sensor); rig.json describes the rig's
# boards (omniscan.rig) and pose.png is a lit, lasers-off image of the rig. With --port the real
# controller triggers the camera (whose software writes frames into --frames); with --emulate the
# virtual controller renders the rig scene through omni-sim. The mirror annulus (rim circle, for
# the receiver's corner search and initial principal point) is found in --rim-image (an image of a
# lit scene showing the whole mirror), else in pose.png, else in the board images (their per-pixel
# range), else the receiver runs without it (OUT/annulus.txt says which; ANNULUS=CX,CY,R_IN,R_OUT
# or ANNULUS=none overrides). Writes OUT/camera.json and OUT/scanner.json (plus every intermediate
# stream). RIG_ANGLES, MODEL and VIEWPOINT set the rig scan's angles and the receiver; BIN: the omni-* tools' directory (else PATH).
set -euo pipefail

usage() { sed -n '2,17p' "$0" | sed 's/^# \{0,1\}//'; exit "${1:-2}"; }
board= boards= rig= pose= rim_image= port= frames= scene= true_camera= true_scanner= out=
angles=${RIG_ANGLES:-14:28:0.5} model=${MODEL:-mei} viewpoint=${VIEWPOINT:-0,0,80}
[ -n "${BIN:-}" ] && PATH="$BIN:$PATH"
while [ $# -gt 0 ]; do
  case "$1" in
    --board) board=$2; shift 2 ;;
    --boards) boards=$2; shift 2 ;;
    --rig) rig=$2; shift 2 ;;
    --pose-image) pose=$2; shift 2 ;;
    --rim-image) rim_image=$2; shift 2 ;;
    --port) port=$2; shift 2 ;;
    --frames) frames=$2; shift 2 ;;
    --emulate) scene=$2; shift 2 ;;
    --true-camera) true_camera=$2; shift 2 ;;
    --true-scanner) true_scanner=$2; shift 2 ;;
    --angles) angles=$2; shift 2 ;;
    --out) out=$2; shift 2 ;;
    -h|--help) usage 0 ;;
    *) echo "calibrate.sh: unknown argument $1" >&2; usage ;;
  esac
done
[ -n "$board" ] && [ -n "$boards" ] && [ -n "$rig" ] && [ -n "$pose" ] && [ -n "$out" ] || usage
mkdir -p "$out"

# The mirror annulus: from the first of --rim-image, the pose image and the board images whose rim
# is visible all round; ANNULUS=CX,CY,R_IN,R_OUT overrides, ANNULUS=none turns it off.
annulus=${ANNULUS:-}
: > "$out/annulus.txt"
if [ -z "$annulus" ]; then
  for source in ${rim_image:+"$rim_image"} "$pose" "$boards"; do
    annulus=$(omni-calib-receiver find-annulus "$source" 2>> "$out/annulus.txt") && break
  done
  [ -n "$annulus" ] || annulus=none
fi
echo "annulus: $annulus" >> "$out/annulus.txt"
receiver_args=()
[ "$annulus" != none ] && receiver_args+=(--annulus "$annulus")

echo "calibrate.sh: receiver ($model) from $boards, annulus $annulus" >&2
omni-calib-receiver --board "$board" --model "$model" --viewpoint-mm "$viewpoint" "${receiver_args[@]}" \
  --save-corners "$out/corners.json" -o "$out/camera.json" "$boards" 2> >(tee "$out/receiver.txt" >&2)

echo "calibrate.sh: rig scan" >&2
scan_args=(--camera "$out/camera.json" --scanner none --out "$out/rig_scan" --angles "$angles" --laser-off)
[ -n "$port" ] && scan_args+=(--port "$port")
[ -n "$frames" ] && scan_args+=(--frames "$frames")
[ -n "$scene" ] && scan_args+=(--emulate "$scene")
[ -n "$true_camera" ] && scan_args+=(--true-camera "$true_camera")
[ -n "$true_scanner" ] && scan_args+=(--true-scanner "$true_scanner")
STAGES=stripes "$(dirname "$0")/scan.sh" "${scan_args[@]}"

echo "calibrate.sh: light planes" >&2
omni-calib-plane fit --camera "$out/camera.json" --rig "$rig" --pose-image "$pose" \
  --stripes "$out/rig_scan/stripes.jsonl" -o "$out/scanner.json" 2> >(tee "$out/planes.txt" >&2)
echo "calibrate.sh: wrote $out/camera.json and $out/scanner.json" >&2
