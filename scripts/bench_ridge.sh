#!/usr/bin/env bash
# Stripe-centre speed: omni-ridge's estimators (criterion, one core, 8-bit frames in memory)
# beside a numpy/OpenCV reference of the paper's threshold + centroid on the same frames, and
# the ratio. Usage: scripts/bench_ridge.sh   (needs python3 with numpy and opencv-python-headless)
set -euo pipefail
cd "$(dirname "$0")/.."
dir="${OMNI_RIDGE_BENCH_DIR:-$(mktemp -d)}"
mkdir -p "$dir"
log="$dir/rust.log"
OMNI_RIDGE_BENCH_DIR="$dir" cargo bench -p omni-vision --bench ridge -- --warm-up-time 1 --measurement-time 3 | tee "$log"
read -r _ cx cy rin rout < <(grep '^CIRCLE' "$log")
echo
echo "== omni-ridge (Rust, one core) =="
grep '^SUMMARY' "$log"
echo "== numpy/OpenCV reference (one core) =="
if ! python3 -c 'import numpy, cv2' 2>/dev/null; then
    echo "numpy/OpenCV missing: pip install numpy opencv-python-headless" >&2
    exit 1
fi
python3 scripts/bench_ridge.py "$dir"/*.png --centre "$cx" "$cy" --radii "$rin" "$rout" | tee "$dir/python.log"
echo "== ratio (Python ÷ Rust centroid, thread CPU time per frame, medians) =="
while read -r _ name py _; do
    rust=$(awk -v n="$name" '$1 == "SUMMARY" && $2 == "centroid" && $3 == n {
        for (i = 4; i < NF; i++) if ($i == "median") print $(i + 1) }' "$log")
    awk -v n="$name" -v p="$py" -v r="$rust" 'BEGIN { printf "%s: Rust %.3f ms/MP, Python %.3f ms/MP, Rust is %.1fx faster\n", n, r, p, p / r }'
done < "$dir/python.log"
