# omni-ridge on real photographs of a red line laser (../shared/data/real-laser-handheld): the
# stripe on a flat board must be a straight line once OpenCV has undistorted the frame;
# scripts/real_laser.py scores omni-ridge beside a column-centroid reference.
# `make test-real-laser` asserts the targets (bin/omni-ridge/tests/test_real_laser.py, the
# debug build); `make real-laser` prints the per-frame table with the demo build, without and
# with --one-stripe-per column. Where OpenCV finds no board in a stripe frame,
# omni-calib-receiver (beside omni-ridge) gives its outline.
RIDGE_PYTHON ?= .venv/bin/python

.PHONY: test-real-laser real-laser
EXTRA_TESTS += test-real-laser

test-real-laser: test-build
	@test -x $(RIDGE_PYTHON) || { echo "test-real-laser: $(RIDGE_PYTHON) is missing; run scripts/deps.sh" >&2; exit 1; }
	OMNI_RIDGE=$(DEBUG_DIR)/omni-ridge $(RIDGE_PYTHON) -m pytest -q bin/omni-ridge/tests/test_real_laser.py

real-laser:
	$(CARGO) build -p omni-ridge -p omni-calib-receiver --profile demo
	OMNI_RIDGE=$(TARGET_DIR)/demo/omni-ridge $(RIDGE_PYTHON) scripts/real_laser.py -- --laser red
	@echo "With the reflections dropped (--one-stripe-per column):"
	OMNI_RIDGE=$(TARGET_DIR)/demo/omni-ridge $(RIDGE_PYTHON) scripts/real_laser.py -- --laser red --one-stripe-per column
