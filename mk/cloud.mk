# Point-cloud formats and ROS 2 bags read back by independent Python readers
# (tests/cloud/test_cloud_formats.py; the readers come from scripts/deps.d/40-cloud.sh).
# `make bench` also runs the Open3D checks (tests/cloud/bench_open3d.py, target bench-cloud-open3d).
.PHONY: test-cloud bench-cloud-open3d cloud-venv-check
cloud-venv-check:
	@test -x .venv/bin/python || { echo "cloud: .venv is missing; run scripts/deps.sh" >&2; exit 1; }

test-cloud: test-build cloud-venv-check
	OMNI_BIN=$(DEBUG_DIR) .venv/bin/python -m pytest -q tests/cloud/test_cloud_formats.py

bench-cloud-open3d: test-build cloud-venv-check
	.venv/bin/python -m pip install -q --disable-pip-version-check open3d
	cd tests/cloud && OMNI_BIN=$(DEBUG_DIR) ../../.venv/bin/python -m pytest -q -s bench_open3d.py

EXTRA_TESTS += test-cloud
