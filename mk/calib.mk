# omni-calib-receiver's interop files checked against independent implementations (OpenCV's
# cv2.omnidir, cv2.projectPoints, cv2.fisheye.projectPoints, OCamCalib's cam2world/world2cam
# written from its documentation), and its pinhole and fisheye fits against OpenCV's on the real
# hand-held photographs (../shared/data/real-laser-handheld, read in place; about 10 s):
# bin/omni-calib-receiver/tests/interop.py; and its corners against OpenCV's cornerSubPix on
# the real sets in ../shared/data (bin/omni-calib-receiver/tests/test_real_corners.py, about
# 45 s; `scripts/real_corners.py --bin DIR` prints the table). Needs scripts/deps.sh (the .venv
# packages).
CALIB_PYTHON ?= .venv/bin/python

.PHONY: test-calib-interop
test-calib-interop: test-build
	@test -x $(CALIB_PYTHON) || { echo "test-calib-interop: $(CALIB_PYTHON) is missing; run scripts/deps.sh" >&2; exit 1; }
	$(CALIB_PYTHON) bin/omni-calib-receiver/tests/interop.py $(DEBUG_DIR)/omni-calib-receiver
	OMNI_CALIB_RECEIVER=$(DEBUG_DIR)/omni-calib-receiver $(CALIB_PYTHON) -m pytest -q bin/omni-calib-receiver/tests/test_real_corners.py

EXTRA_TESTS += test-calib-interop
