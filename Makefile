# omniscan — see README.md. Every target works on a fresh machine (after .ci/run's installs).
CARGO ?= cargo
OUT ?= out/demo
FUZZ_SECONDS ?= 60

.PHONY: all build test test-rust deps lint tools fmt bench demo fuzz clean

# Parts of the build with their own tests (firmware, Python, ...): each appends to EXTRA_TESTS;
# FEATURE_TESTS run last, because they build crates with cargo features the others do not use.
EXTRA_TESTS :=
FEATURE_TESTS :=
.DEFAULT_GOAL := all
-include mk/*.mk

all: build

build:
	$(CARGO) build --workspace --release

# rustfmt and clippy are rustup components a fresh toolchain may lack: say how to get them.
tools:
	@$(CARGO) fmt --version >/dev/null 2>&1 || { echo "make: rustfmt is missing; install it with: rustup component add rustfmt clippy" >&2; exit 1; }
	@$(CARGO) clippy --version >/dev/null 2>&1 || { echo "make: clippy is missing; install it with: rustup component add rustfmt clippy" >&2; exit 1; }

lint: tools
	$(CARGO) fmt --all -- --check
	$(CARGO) clippy --workspace --all-targets -- -D warnings

test: deps lint test-rust $(EXTRA_TESTS) $(FEATURE_TESTS)

test-rust:
	$(CARGO) test --workspace

# System packages and Python readers the tests need (scripts/deps.d/); quick when present.
deps:
	scripts/deps.sh

fmt:
	$(CARGO) fmt --all

bench: build
	scripts/bench.sh

# The demo profile (Cargo.toml): no LTO, parallel codegen, a fraction of the release build time.
demo:
	$(CARGO) build --workspace --profile demo
	OUT=$(OUT) BIN=$(CURDIR)/target/demo scripts/demo.sh

# Mutation fuzzing of every reader, FUZZ_SECONDS per target (crates/omni-fuzz; crashes are
# saved to target/fuzz-crashes/). The fuzz profile keeps overflow checks and debug assertions.
fuzz:
	$(CARGO) run --profile fuzz -p omni-fuzz -- --target all --seconds $(FUZZ_SECONDS)

clean:
	$(CARGO) clean
	rm -rf out
