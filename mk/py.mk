# The Python package (python/, PyO3 + maturin) and the batch workflow (workflow/, Snakemake):
# `make test-py` builds the package into the project venv and runs its pytest suite,
# `make test-workflow` runs the workflow on tiny simulated scans. scripts/deps.d/50-py.sh
# installs maturin, pytest, OpenCV (cv2.omnidir), plyfile and snakemake into the venv.
PY_VENV ?= .venv
# One target directory for the workspace and the package (a workspace of its own, see
# docs/DECISIONS.md), so the package reuses the crates `cargo test --workspace` compiled.
PY_TARGET_DIR := $(or $(CARGO_TARGET_DIR),$(CURDIR)/target)
# The tools the tests run, in the dev profile `cargo test --workspace` builds.
PY_TOOLS := omni-sim omni-ridge omni-triangulate omni-merge omni-eval omni-calib-receiver omni-calib-plane

.PHONY: test-py test-workflow py-develop py-tools py-lint py-venv-check
EXTRA_TESTS += test-py test-workflow

py-venv-check:
	@test -x $(PY_VENV)/bin/maturin || { echo "make: $(PY_VENV)/bin/maturin is missing; run scripts/deps.sh" >&2; exit 1; }

# Builds the extension (debug profile: python/Cargo.toml) and installs it into the venv.
py-develop: py-venv-check
	CARGO_TARGET_DIR=$(PY_TARGET_DIR) VIRTUAL_ENV=$(CURDIR)/$(PY_VENV) PATH=$(CURDIR)/$(PY_VENV)/bin:$$PATH \
		$(PY_VENV)/bin/maturin develop --quiet -m python/Cargo.toml

py-lint: py-venv-check
	$(CARGO) fmt --manifest-path python/Cargo.toml -- --check
	CARGO_TARGET_DIR=$(PY_TARGET_DIR) PYO3_PYTHON=$(CURDIR)/$(PY_VENV)/bin/python \
		$(CARGO) clippy --manifest-path python/Cargo.toml --all-targets -- -D warnings

py-tools:
	$(CARGO) build $(addprefix -p ,$(PY_TOOLS))

test-py: py-lint py-develop py-tools
	OMNISCAN_BIN=$(PY_TARGET_DIR)/debug $(PY_VENV)/bin/python -m pytest -q python/tests

test-workflow: py-venv-check py-tools
	OMNISCAN_BIN=$(PY_TARGET_DIR)/debug $(PY_VENV)/bin/python -m pytest -q workflow/tests
