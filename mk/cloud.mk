# Point-cloud formats and ROS 2 bags read back by independent Python readers
# (tests/cloud/test_cloud_formats.py; the readers come from scripts/deps.d/40-cloud.sh).
# `make bench` also runs the Open3D checks (tests/cloud/bench_open3d.py, target bench-cloud-open3d).
# `make test-cloudcompare` (optional, not in `make test`: Debian's cloudcompare package took 65 s
# and 241 MB to install here) reads the PLY files with CloudCompare's command line.
.PHONY: test-cloud test-cloudcompare bench-cloud-open3d cloud-venv-check
cloud-venv-check:
	@test -x .venv/bin/python || { echo "cloud: .venv is missing; run scripts/deps.sh" >&2; exit 1; }

test-cloud: test-build cloud-venv-check
	OMNI_BIN=$(DEBUG_DIR) .venv/bin/python -m pytest -q tests/cloud/test_cloud_formats.py

test-cloudcompare: test-build cloud-venv-check
	@command -v CloudCompare >/dev/null || { test "$$(id -u)" = 0 && apt-get install -y -q cloudcompare >/dev/null; } \
	  || { echo "test-cloudcompare: CloudCompare is missing; run: sudo apt-get install -y cloudcompare" >&2; exit 1; }
	cd tests/cloud && OMNI_BIN=$(DEBUG_DIR) ../../.venv/bin/python -m pytest -q -rs test_cloudcompare.py

bench-cloud-open3d: test-build cloud-venv-check
	.venv/bin/python -m pip install -q --disable-pip-version-check open3d
	cd tests/cloud && OMNI_BIN=$(DEBUG_DIR) ../../.venv/bin/python -m pytest -q -s bench_open3d.py

EXTRA_TESTS += test-cloud
