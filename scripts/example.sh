#!/usr/bin/env bash
# The main job on an example scene: trace a Luneburg beam through the ray-table tracer.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
cargo build --release --locked -p grin-cli
mkdir -p out
./target/release/grin --help
