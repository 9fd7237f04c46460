# omni-calib-receiver's interop files checked against independent implementations (OpenCV's
# cv2.omnidir, OCamCalib's cam2world/world2cam written from its documentation):
# bin/omni-calib-receiver/tests/interop.py. Needs scripts/deps.sh (the .venv packages).
CALIB_BIN := $(or $(CARGO_TARGET_DIR),target)/debug/omni-calib-receiver
CALIB_PYTHON ?= .venv/bin/python

.PHONY: test-calib-interop
test-calib-interop:
	@test -x $(CALIB_PYTHON) || { echo "test-calib-interop: $(CALIB_PYTHON) is missing; run scripts/deps.sh" >&2; exit 1; }
	$(CARGO) build -p omni-calib-receiver
	$(CALIB_PYTHON) bin/omni-calib-receiver/tests/interop.py $(CALIB_BIN)

EXTRA_TESTS += test-calib-interop
