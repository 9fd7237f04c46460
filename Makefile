# omniscan — see README.md. Every target works on a fresh machine (after .ci/run's installs).
CARGO ?= cargo
OUT ?= out/demo

.PHONY: all build test lint fmt bench demo clean

all: build

build:
	$(CARGO) build --workspace --release

lint:
	$(CARGO) fmt --all -- --check
	$(CARGO) clippy --workspace --all-targets -- -D warnings

test: lint
	$(CARGO) test --workspace

fmt:
	$(CARGO) fmt --all

bench: build
	scripts/bench.sh

demo: build
	OUT=$(OUT) scripts/demo.sh

clean:
	$(CARGO) clean
	rm -rf out
