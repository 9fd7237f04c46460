#!/usr/bin/env bash
# Installs what `make test` needs beyond the Rust toolchain, idempotently: each part of the
# project that needs a system package or a Python reader has one file in scripts/deps.d/.
# Quick when everything is present; needs root (or sudo) only when something is missing.
set -euo pipefail
cd "$(dirname "$0")/.."
# shellcheck source=deps.d/lib.sh
. scripts/deps.d/lib.sh
for part in scripts/deps.d/[0-9]*.sh; do
  [ -e "$part" ] || continue
  # shellcheck disable=SC1090
  . "$part"
done
