# GenICam frame source (omni-trigger --camera aravis:ID, cargo feature `aravis`): the Makefile's
# FEATURES turns the feature on wherever libaravis-0.8 is installed, so `make test-rust` lints
# and runs the end-to-end tests against Aravis's fake GigE Vision camera on `lo`
# (bin/omni-trigger/tests/aravis.rs: they wait on the camera's clock, about 55 s for 3 s of CPU,
# so `make test` runs them beside the other tests).
# `make test-arv` runs those tests alone.
# scripts/deps.d/30-arv.sh installs libaravis-dev and aravis-tools.
.PHONY: test-arv
test-arv:
	@command -v arv-fake-gv-camera-0.8 >/dev/null && pkg-config --exists aravis-0.8 || { \
	  echo "test-arv: libaravis-0.8 or arv-fake-gv-camera-0.8 is missing; run scripts/deps.sh" >&2; exit 1; }
	$(CARGO) test $(WORKSPACE) --test aravis
