# The fixed light plane of the real hand-held line-laser sensor (../shared/data/real-laser-handheld,
# read in place): `make real-plane` runs omni-calib-receiver --model mei on the board frames,
# omni-calib-plane fixed on the stripe frames (omni-ridge's detector, and a column-centroid
# reference for comparison), fits the receiver's other models beside OpenCV's on the same corners
# (scripts/receiver_models.py) and prints one table; out/real-plane/ keeps camera.json,
# scanner.json, the reports and plane.png. The assertions are Rust tests (`make test`:
# crates/omni-calib/tests/fixed_plane.rs, bin/omni-calib-plane/tests/fixed.rs), the receiver
# models' in bin/omni-calib-receiver/tests/interop.py (`make test-calib-interop`). The virtual
# sensor's rendered fixed plane is crates/omni-calib/tests/fixed_plane_rendered.rs (`make test`).
PLANE_PYTHON ?= .venv/bin/python

.PHONY: real-plane
real-plane:
	@test -x $(PLANE_PYTHON) || { echo "real-plane: $(PLANE_PYTHON) is missing; run scripts/deps.sh" >&2; exit 1; }
	$(CARGO) build $(WORKSPACE) --bin omni-calib-receiver --bin omni-calib-plane
	$(PLANE_PYTHON) scripts/real_plane.py --bin $(DEBUG_DIR) --out out/real-plane
