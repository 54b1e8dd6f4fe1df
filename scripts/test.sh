#!/usr/bin/env bash
# Run every test of the workspace (unit, physics, GPU on lavapipe, end-to-end).
set -euo pipefail
cd "$(dirname "$0")/.."
# Mesa's device-select layer probes for a Wayland display on every GPU device and prints
# "XDG_RUNTIME_DIR is invalid" on a headless machine: harmless, and off with this.
export NODEVICE_SELECT="${NODEVICE_SELECT:-1}"
bash scripts/setup.sh
cargo test --workspace --locked "$@"
