# The Python package (python/, PyO3, a workspace member) and the batch workflow (workflow/,
# Snakemake). `make test-py` puts the extension `make test-build` compiled into python/omniscan/
# (where `maturin develop` would put it) and runs the pytest suite on it; `make test-workflow`
# runs the workflow on tiny simulated scans, locally and, as root, through Slurm on a one-node
# cluster the test brings up and tears down (scripts/slurm_cluster.sh; about 2 min, mostly the
# executor plugin's status waits); `make test-slurm` runs the Slurm part alone (with the local
# run it compares with); `make py-develop` is maturin's editable install into the venv, for
# development. scripts/deps.d/50-py.sh installs maturin, pytest, OpenCV (cv2.omnidir), plyfile
# and snakemake into the venv; 70-slurm.sh Slurm, munge and the Snakemake Slurm plugin.
PY_VENV ?= .venv
PY_EXT_SUFFIX = $(shell $(PY_VENV)/bin/python -c 'import sysconfig; print(sysconfig.get_config_var("EXT_SUFFIX"))')

.PHONY: test-py test-workflow test-slurm py-develop py-extension py-venv-check
EXTRA_TESTS += test-py test-workflow

py-venv-check:
	@test -x $(PY_VENV)/bin/pytest || { echo "make: $(PY_VENV)/bin/pytest is missing; run scripts/deps.sh" >&2; exit 1; }

# The cdylib under the name CPython imports it by.
py-extension: test-build py-venv-check
	cp --remove-destination $(DEBUG_DIR)/lib_native.so python/omniscan/_native$(PY_EXT_SUFFIX)

py-develop: py-venv-check
	VIRTUAL_ENV=$(CURDIR)/$(PY_VENV) PATH=$(CURDIR)/$(PY_VENV)/bin:$$PATH \
		$(PY_VENV)/bin/maturin develop --quiet -m python/Cargo.toml

test-py: py-extension
	PYTHONPATH=$(CURDIR)/python OMNISCAN_BIN=$(DEBUG_DIR) $(PY_VENV)/bin/python -m pytest -q python/tests

test-workflow: test-build py-venv-check
	OMNISCAN_BIN=$(DEBUG_DIR) $(PY_VENV)/bin/python -m pytest -q workflow/tests

test-slurm: test-build py-venv-check
	OMNISCAN_BIN=$(DEBUG_DIR) $(PY_VENV)/bin/python -m pytest -q workflow/tests -k slurm
