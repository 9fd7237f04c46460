# omni-calib-receiver's interop files checked against independent implementations (OpenCV's
# cv2.omnidir, cv2.projectPoints, cv2.fisheye.projectPoints, OCamCalib's cam2world/world2cam
# written from its documentation), and its pinhole and fisheye fits against OpenCV's on the real
# hand-held photographs (../shared/data/real-laser-handheld, read in place; about 10 s):
# bin/omni-calib-receiver/tests/interop.py. Needs scripts/deps.sh (the .venv packages).
CALIB_PYTHON ?= .venv/bin/python

.PHONY: test-calib-interop
test-calib-interop: test-build
	@test -x $(CALIB_PYTHON) || { echo "test-calib-interop: $(CALIB_PYTHON) is missing; run scripts/deps.sh" >&2; exit 1; }
	$(CALIB_PYTHON) bin/omni-calib-receiver/tests/interop.py $(DEBUG_DIR)/omni-calib-receiver

EXTRA_TESTS += test-calib-interop
