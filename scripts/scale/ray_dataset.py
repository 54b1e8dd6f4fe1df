"""A BOS dataset on Ray: one task per shard, each a worker on one CPU, writing into one
folder; the same files as one process (or `grin dataset bos`) writes. Prints pairs per
second for one process and for Ray, and each worker's peak memory.

    .venv/bin/python scripts/scale/ray_dataset.py --count 200 --out out/ray-bos
"""

import argparse
import json
import os
import resource
import shutil
import subprocess
import sys
import time

import ray

import grin
from grin import dataset


def write_shard(folder, count, seed, size, index, shards):
    start = time.perf_counter()
    summary = dataset.write_bos(folder, count, seed=seed, size=size,
                                indices=dataset.shard(count, index, shards))
    summary["task_seconds"] = time.perf_counter() - start
    # Peak resident memory of this worker process (kB on Linux).
    summary["peak_rss_mb"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    return summary


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--count", type=int, default=200)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--size", default="128x96")
    ap.add_argument("--cpus", type=int, default=2)
    ap.add_argument("--out", default="out/ray-bos")
    a = ap.parse_args()
    size = tuple(int(v) for v in a.size.split("x"))
    report = {"count": a.count, "size": a.size, "grin": grin.__version__}

    # One process, all cores to grin's own threads (rayon).
    one = a.out + "-one-process"
    shutil.rmtree(one, ignore_errors=True)
    t = time.perf_counter()
    dataset.write_bos(one, a.count, seed=a.seed, size=size)
    report["one_process_pairs_per_second"] = a.count / (time.perf_counter() - t)
    report["one_process_peak_rss_mb"] = (
        resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024)

    # One process, one grin thread: what each Ray worker is.
    single = a.out + "-one-thread"
    shutil.rmtree(single, ignore_errors=True)
    code = ("import time, grin.dataset as d; t = time.perf_counter(); "
            f"d.write_bos({single!r}, {a.count}, seed={a.seed}, size={size!r}); "
            "print(time.perf_counter() - t)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True, env={**os.environ, "RAYON_NUM_THREADS": "1"})
    report["one_thread_pairs_per_second"] = a.count / float(out.stdout.split()[-1])
    shutil.rmtree(single, ignore_errors=True)

    # Ray: a task per CPU, one grin thread each.
    shutil.rmtree(a.out, ignore_errors=True)
    ray.init(num_cpus=a.cpus, include_dashboard=False, log_to_driver=False,
             runtime_env={"env_vars": {"RAYON_NUM_THREADS": "1"}})
    task = ray.remote(num_cpus=1)(write_shard)
    # Start the workers (imports, grin's first use) before timing.
    ray.get([task.remote(a.out + "-warm", 2 * a.cpus, 1, (16, 16), i, a.cpus)
             for i in range(a.cpus)])
    t = time.perf_counter()
    shards = ray.get([task.remote(a.out, a.count, a.seed, size, i, a.cpus)
                      for i in range(a.cpus)])
    seconds = time.perf_counter() - t
    ray.shutdown()
    shutil.rmtree(a.out + "-warm", ignore_errors=True)
    if not os.path.exists(os.path.join(a.out, "manifest.jsonl")):
        dataset.write_bos(a.out, a.count, seed=a.seed, size=size)
    report["ray_pairs_per_second"] = a.count / seconds
    report["ray_over_one_process"] = (report["ray_pairs_per_second"]
                                      / report["one_process_pairs_per_second"])
    report["ray_over_one_thread"] = (report["ray_pairs_per_second"]
                                     / report["one_thread_pairs_per_second"])
    report["ray_worker_peak_rss_mb"] = [round(s["peak_rss_mb"], 1) for s in shards]
    same = all(
        open(os.path.join(one, n), "rb").read() == open(os.path.join(a.out, n), "rb").read()
        for n in os.listdir(one))
    report["ray_files_equal_one_process"] = same and sorted(os.listdir(one)) == sorted(os.listdir(a.out))
    print(json.dumps(report, indent=2))


if __name__ == "__main__":
    main()
