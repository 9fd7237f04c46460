# omni-live's ROS 2 output read by a ROS-free DDS peer (PyPI cyclonedds) in a network namespace
# of the test's own (bin/omni-live/tests/test_live.py; needs root for `unshare --net`).
LIVE_PYTHON ?= .venv/bin/python

.PHONY: test-live
EXTRA_TESTS += test-live

test-live: test-build
	@test -x $(LIVE_PYTHON) || { echo "test-live: $(LIVE_PYTHON) is missing; run scripts/deps.sh" >&2; exit 1; }
	OMNI_BIN=$(DEBUG_DIR) $(LIVE_PYTHON) -m pytest -q bin/omni-live/tests/test_live.py
