#!/usr/bin/env bash
# A 48-frame OpenVDB sequence rendered twice on the GPU backend with one bake cache:
# the first render bakes every frame's grid and stores it, the second bakes nothing (every
# frame a cache hit) and writes the same images. Prints the counts and both wall times.
#
#   bash scripts/bench_sequence_cache.sh [--grin target/release/grin] [--frames 48] [--size 160x90]
#
# Needs Debian's python3-openvdb (/usr/bin/python3, module pyopenvdb) and numpy to write the frames.
set -euo pipefail
GRIN=target/release/grin
FRAMES=48
SIZE=160x90
while [ $# -gt 0 ]; do
    case "$1" in
        --grin) GRIN=$2; shift 2 ;;
        --frames) FRAMES=$2; shift 2 ;;
        --size) SIZE=$2; shift 2 ;;
        *) echo "unknown argument $1" >&2; exit 2 ;;
    esac
done
GRIN=$(realpath "$GRIN")
work=$(mktemp -d /tmp/grin-seq-cache.XXXXXX)
trap 'rm -rf "$work"' EXIT
/usr/bin/python3 -c "import numpy" 2>/dev/null || apt-get install -y -qq python3-numpy >/dev/null
# A rising, widening column of hot gas (delta_n < 0) on a 64^3 grid, one file a frame.
/usr/bin/python3 - "$work" "$FRAMES" <<'PY'
import sys
import numpy as np
import pyopenvdb as vdb
out, frames = sys.argv[1], int(sys.argv[2])
n = 64
ax = (np.arange(n) - n / 2 + 0.5) / n
x, y, z = np.meshgrid(ax, ax, ax, indexing="ij")
for f in range(1, frames + 1):
    s = f / frames
    top = -0.3 + 0.6 * s
    width = 0.06 + 0.05 * (y + 0.5) + 0.02 * np.sin(9 * y + 0.5 * f)
    column = np.exp(-((x - 0.05 * np.sin(4 * y + 0.3 * f)) ** 2 + z ** 2) / width ** 2)
    column *= 1 / (1 + np.exp((y - top) / 0.03))
    g = vdb.FloatGrid()
    g.name = "delta_n"
    g.copyFromArray((-2e-3 * column).astype(np.float32), ijk=(-n // 2,) * 3, tolerance=1e-7)
    g.transform = vdb.createLinearTransform(voxelSize=1.0 / n)
    vdb.write(f"{out}/column_{f:04d}.vdb", grids=[g])
PY
cat > "$work/seq.toml" <<'TOML'
[camera]
position = [0.0, 0.0, -2.2]
look_at = [0.0, 0.0, 0.0]
fov_y_deg = 30.0
[[object]]
shape = { plane = { point = [0.0, 0.0, 1.0], normal = [0.0, 0.0, -1.0] } }
material = { checker = { color_a = [0.9, 0.9, 0.9], color_b = [0.1, 0.1, 0.1], scale = 0.04 } }
[medium]
bounds = { box = { min = [-0.5, -0.5, -0.5], max = [0.5, 0.5, 0.5] } }
ambient_index = 1.000293
field = { kind = "vdb", path = "column_####.vdb", grid = "delta_n", map = { index = { delta = true } } }
TOML
render() {
    local tag=$1 start end
    start=$(date +%s.%N)
    GRIN_CACHE_DIR="$work/cache" "$GRIN" render "$work/seq.toml" --backend gpu --size "$SIZE" \
        --frames "1..$FRAMES" --json -o "$work/$tag.####.exr" > "$work/$tag.json" 2> "$work/$tag.log"
    end=$(date +%s.%N)
    python3 - "$work/$tag.json" "$tag" "$start" "$end" <<'PY'
import collections, json, sys
frames = json.load(open(sys.argv[1]))
counts = collections.Counter(f.get("bake_cache", "none") for f in frames)
print(f"{sys.argv[2]}: {len(frames)} frames in {float(sys.argv[4]) - float(sys.argv[3]):.1f} s, "
      f"bake cache: {dict(counts)}")
PY
}
render first
render second
same=0
for f in $(seq -f %04g 1 "$FRAMES"); do
    cmp -s "$work/first.$f.exr" "$work/second.$f.exr" && same=$((same + 1))
done
echo "images identical in both renders: $same of $FRAMES"
