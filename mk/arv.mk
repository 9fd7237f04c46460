# GenICam frame source (omni-trigger --camera aravis:ID, cargo feature `aravis`): lint omni-hw and
# omni-trigger with the feature on, and run the end-to-end tests against Aravis's fake GigE
# Vision camera on `lo` (the rest of both crates' tests ran in test-rust; scripts/deps.d/30-arv.sh
# installs libaravis-dev and aravis-tools).
.PHONY: test-arv
test-arv:
	@command -v arv-fake-gv-camera-0.8 >/dev/null && pkg-config --exists aravis-0.8 || { \
	  echo "test-arv: libaravis-0.8 or arv-fake-gv-camera-0.8 is missing; run scripts/deps.sh" >&2; exit 1; }
	$(CARGO) clippy -p omni-hw -p omni-trigger --features omni-trigger/aravis --all-targets -- -D warnings
	$(CARGO) test -p omni-trigger --features aravis --test aravis

# Last in `make test` (FEATURE_TESTS): building with the feature rebuilds omni-hw and what uses
# it, which the other parts would otherwise build again without it.
FEATURE_TESTS += test-arv
