#!/usr/bin/env bash
# Run every test of the workspace (unit, physics, GPU on lavapipe, end-to-end).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
cargo test --workspace --locked "$@"
