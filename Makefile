# omniscan — see README.md. Every target works on a fresh machine (after .ci/run's installs).
CARGO ?= cargo
OUT ?= out/demo
FUZZ_SECONDS ?= 60

.PHONY: all build test test-suite test-build test-rust test-rust-main test-rust-side deps lint tools fmt bench bench-run demo fuzz clean

# One cargo feature set for every command of `make test`, so that each crate is compiled once
# and the parts below reuse the workspace's debug build: the GenICam frame source is on wherever
# libaravis-0.8 is installed (scripts/deps.sh installs it; `make test` evaluates this after).
ifndef FEATURES
FEATURES := $(shell pkg-config --exists aravis-0.8 2>/dev/null && echo --features omni-trigger/aravis)
endif
WORKSPACE := --workspace $(FEATURES)
# Where cargo puts what it builds: $CARGO_TARGET_DIR when set (a shared build directory, as on
# clusters and in CI; relative to this directory, as cargo takes it), else target/. Every target
# that runs a built tool or writes beside the build takes it from here.
TARGET_DIR := $(abspath $(or $(CARGO_TARGET_DIR),$(CURDIR)/target))
# The tools and the Python extension as `make test-build` leaves them.
DEBUG_DIR := $(TARGET_DIR)/debug

# Parts of the build with their own tests (firmware, Python, ...): each appends to EXTRA_TESTS.
EXTRA_TESTS :=
.DEFAULT_GOAL := all
-include mk/*.mk

all: build

# The tools; the Python package is built by pip or maturin (python/), not here. With $(FEATURES),
# so that omni-trigger drives GenICam cameras wherever libaravis is installed (and `make bench`
# runs a real scan from Aravis's fake camera).
build:
	$(CARGO) build --workspace --exclude omniscan-py --release $(FEATURES)

# rustfmt and clippy are rustup components a fresh toolchain may lack: say how to get them.
tools:
	@$(CARGO) fmt --version >/dev/null 2>&1 || { echo "make: rustfmt is missing; install it with: rustup component add rustfmt clippy" >&2; exit 1; }
	@$(CARGO) clippy --version >/dev/null 2>&1 || { echo "make: clippy is missing; install it with: rustup component add rustfmt clippy" >&2; exit 1; }

# Clippy with $(FEATURES) sees the feature-gated code; `cargo check -p omni-trigger` keeps the
# build without the feature (a machine without libaravis) compiling.
lint: tools
	$(CARGO) fmt --all -- --check
	$(CARGO) clippy $(WORKSPACE) --all-targets -- -D warnings
	$(CARGO) check -q -p omni-trigger

# The installs first, then a fresh make, so that FEATURES sees what deps installed.
test: deps
	$(MAKE) --no-print-directory test-suite

# The build before clippy: clippy then reuses the build's dependencies (about 45 s instead of
# 2.5-4 min when it runs first on a clean target, which would check every dependency again).
test-suite: test-build lint test-rust $(EXTRA_TESTS)

# Everything `cargo test` compiles, plus the Python extension (a cdylib, which no test target
# builds), with one feature resolution: the parts' tests run these binaries without a rebuild.
test-build:
	$(CARGO) build $(WORKSPACE) --lib --bins --tests --examples

# Two lanes at once: the reduced demo (one core's worth of pipes) and the GenICam tests (they
# wait on the fake camera's clock) run beside the other tests, which keep both cores busy. Each
# lane's output is printed when it ends.
SIDE_TESTS := --test demo $(if $(FEATURES),--test aravis)
test-rust: test-build
	@$(MAKE) --no-print-directory -j2 --output-sync=target test-rust-main test-rust-side

test-rust-main:
	$(CARGO) test $(WORKSPACE) -- --skip reduced_demo_meets_the_targets --skip gige_camera::

test-rust-side:
	$(CARGO) test $(WORKSPACE) $(SIDE_TESTS)

# System packages and Python readers the tests need (scripts/deps.d/); quick when present.
deps:
	scripts/deps.sh

fmt:
	$(CARGO) fmt --all

# The installs first, as for `make test`: the Open3D checks read through the venv, the live
# bench needs its cyclonedds, and FEATURES must see libaravis for the fake-camera scan.
bench: deps
	$(MAKE) --no-print-directory bench-run

bench-run: build
	CARGO_TARGET_DIR=$(TARGET_DIR) scripts/bench.sh

# The demo profile (Cargo.toml): no LTO, parallel codegen, a fraction of the release build time.
demo:
	$(CARGO) build --workspace --exclude omniscan-py --profile demo
	OUT=$(OUT) BIN=$(TARGET_DIR)/demo scripts/demo.sh

# Mutation fuzzing of every reader, FUZZ_SECONDS per target (crates/omni-fuzz; crashes are
# saved to $(TARGET_DIR)/fuzz-crashes/). The fuzz profile keeps overflow checks and debug assertions.
fuzz:
	$(CARGO) run --profile fuzz -p omni-fuzz -- --target all --seconds $(FUZZ_SECONDS) --crashes $(TARGET_DIR)/fuzz-crashes

clean:
	$(CARGO) clean
	rm -rf out
