#!/usr/bin/env bash
# A BOS dataset as a Slurm job array: each array task renders one contiguous shard of the
# samples into the same folder; a retried or requeued task skips the samples that are
# complete. The task that finishes last writes manifest.jsonl (else rerun one task: it
# skips everything and writes it).
#
#   sbatch --array=0-7 scripts/scale/slurm_bos.sh            # on a cluster
#   for i in 0 1 2 3; do                                      # here, without Slurm
#     SLURM_ARRAY_TASK_ID=$i SLURM_ARRAY_TASK_COUNT=4 bash scripts/scale/slurm_bos.sh &
#   done; wait
#
#SBATCH --job-name=grin-bos
#SBATCH --cpus-per-task=2
#SBATCH --mem=1G
#SBATCH --time=01:00:00
#SBATCH --requeue
set -euo pipefail
grin="${GRIN:-grin}"
out="${OUT:-out/slurm-bos}"
count="${COUNT:-200}"
# Slurm numbers array tasks from the --array range: with --array=0-(N-1) the task id is
# the shard index.
"$grin" dataset bos -o "$out" --count "$count" --seed "${SEED:-7}" --size "${SIZE:-128x96}" \
  --shard "${SLURM_ARRAY_TASK_ID:?not a Slurm array task}/${SLURM_ARRAY_TASK_COUNT:?}"
