#!/usr/bin/env bash
# A frame sequence as a Slurm job array: each task renders one contiguous shard of the
# frame list; --skip-existing makes a requeued task finish only what is missing, and
# --seed gives every frame the same noise whichever task renders it.
#
#   sbatch --array=0-3 scripts/scale/slurm_frames.sh
#
#SBATCH --job-name=grin-frames
#SBATCH --cpus-per-task=2
#SBATCH --time=01:00:00
#SBATCH --requeue
set -euo pipefail
grin="${GRIN:-grin}"
"$grin" render "${SCENE:-data/scenes/noise-sphere.toml}" -o "${OUT:-out/frames/noise.####.exr}" \
  --frames "${FRAMES:-1-48}" --shard "${SLURM_ARRAY_TASK_ID:?}/${SLURM_ARRAY_TASK_COUNT:?}" \
  --skip-existing --seed "${SEED:-1}" --backend "${BACKEND:-cpu}" --size "${SIZE:-320x180}"
