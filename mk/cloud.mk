# Point-cloud formats and ROS 2 bags read back by independent Python readers
# (tests/cloud/test_cloud_formats.py; the readers come from scripts/deps.d/40-cloud.sh).
# `make bench` also runs the Open3D checks (tests/cloud/bench_open3d.py, target bench-cloud-open3d).
CLOUD_BIN = $(or $(CARGO_TARGET_DIR),$(CURDIR)/target)/debug

.PHONY: test-cloud bench-cloud-open3d cloud-binaries
cloud-binaries:
	$(CARGO) build -q -p omni-sim -p omni-ridge -p omni-triangulate -p omni-merge
	@test -x .venv/bin/python || { echo "cloud: .venv is missing; run scripts/deps.sh" >&2; exit 1; }

test-cloud: cloud-binaries
	OMNI_BIN=$(CLOUD_BIN) .venv/bin/python -m pytest -q tests/cloud/test_cloud_formats.py

bench-cloud-open3d: cloud-binaries
	.venv/bin/python -m pip install -q --disable-pip-version-check open3d
	cd tests/cloud && OMNI_BIN=$(CLOUD_BIN) ../../.venv/bin/python -m pytest -q -s bench_open3d.py

EXTRA_TESTS += test-cloud
