#!/usr/bin/env bash
# Run every test of the workspace (unit, physics, GPU on lavapipe, end-to-end) and the
# Python package's.
set -euo pipefail
cd "$(dirname "$0")/.."
# Mesa's device-select layer probes for a Wayland display on every GPU device and prints
# "XDG_RUNTIME_DIR is invalid" on a headless machine: harmless, and off with this.
export NODEVICE_SELECT="${NODEVICE_SELECT:-1}"
# The GPU bake cache of this run: its own, so tests neither read nor fill the user's.
if [ -z "${GRIN_CACHE_DIR:-}" ]; then
  GRIN_CACHE_DIR="$(mktemp -d)"
  trap 'rm -rf "$GRIN_CACHE_DIR"' EXIT
fi
export GRIN_CACHE_DIR
bash scripts/setup.sh
# grin-py is a Python extension module: built by maturin and tested by pytest below.
cargo test --workspace --exclude grin-py --locked "$@"
GRIN_BIN="$PWD/target/debug/grin" bash scripts/python.sh test
