#!/usr/bin/env bash
# The main job on an example scene: render the paper's test scene (a GRIN sphere, n highest
# at the centre, in front of a glass and a steel ball) with the wgpu marcher (Mesa's
# lavapipe when there is no GPU) to out/paper-a.exr + out/paper-a.png, then trace a
# Luneburg beam through the ray-table tracer to out/luneburg-rays.csv.
set -euo pipefail
cd "$(dirname "$0")/.."
# Mesa's device-select layer probes for a Wayland display on every GPU device and prints
# "XDG_RUNTIME_DIR is invalid" on a headless machine: harmless, and off with this.
export NODEVICE_SELECT="${NODEVICE_SELECT:-1}"
bash scripts/setup.sh
cargo build --release --locked -p grin-cli
mkdir -p out
grin=./target/release/grin
$grin render data/scenes/paper-a.toml -o out/paper-a.exr --backend gpu

# A parallel beam along +z into the Luneburg lens of data/scenes/luneburg.toml: every ray
# should leave at the antipodal point of the lens (the focus, (0, 0, 1)), see out/luneburg-rays.csv.
python3 - > out/luneburg-rays.in.csv <<'PY'
print("ox,oy,oz,dx,dy,dz")
for i in range(9):
    x = -0.8 + 0.2 * i
    print(f"{x:.6f},0.0,-3.0,0,0,1")
PY
$grin trace data/scenes/luneburg.toml --rays out/luneburg-rays.in.csv -o out/luneburg-rays.csv
echo "example: wrote out/paper-a.exr, out/paper-a.png, out/luneburg-rays.csv"
