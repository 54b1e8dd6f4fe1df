"""The dataset generator from Python: the same samples as the CLI, shards on Ray."""

import filecmp
import os
import subprocess
from pathlib import Path

import numpy as np
import OpenEXR
import pytest

import grin
from grin import dataset

REPO = Path(__file__).resolve().parents[3]
GRIN = Path(os.environ.get("GRIN_BIN", REPO / "target" / "debug" / "grin"))
SIZE = (48, 32)


def cli_dataset(folder, count, seed, *extra):
    done = subprocess.run(
        [str(GRIN), "dataset", "bos", "-o", str(folder), "--count", str(count),
         "--seed", str(seed), "--size", f"{SIZE[0]}x{SIZE[1]}", *extra],
        capture_output=True, text=True)
    assert done.returncode == 0, done.stderr


def same_folders(a, b):
    names = sorted(os.listdir(a))
    assert names == sorted(os.listdir(b))
    match, mismatch, errors = filecmp.cmpfiles(a, b, names, shallow=False)
    assert not mismatch and not errors, mismatch + errors


def test_the_iterator_yields_the_cli_samples(tmp_path):
    cli_dataset(tmp_path, 4, 9)
    samples = list(dataset.bos(2, seed=9, size=SIZE, start=2))
    assert [s.meta["index"] for s in samples] == [2, 3]
    for s in samples:
        i = s.meta["index"]
        with OpenEXR.File(str(tmp_path / f"bos_{i:06}.exr"), separate_channels=True) as f:
            exr = {k: v.pixels for k, v in f.channels().items()}
        assert set(exr) == set(s["channels"])
        for name, array in s["channels"].items():
            assert np.array_equal(array.view(np.uint32), exr[name].view(np.uint32)), name
        h, w = SIZE[1], SIZE[0]
        assert s["displacement"].shape == (h, w, 2) and s["deflection"].shape == (h, w, 2)
        assert s["slice"].shape == (dataset_slice := 64, dataset_slice)
        # The plumes are hot: the index on the slice dips below ambient, never above.
        amb = 1.000272  # air at 20 C, around every generated medium
        assert s["slice"].min() < amb - 1e-5 and s["slice"].max() <= amb + 1e-7
        # The ground truth is consistent: pixels that moved were deflected.
        moved = np.hypot(*np.moveaxis(s["displacement"], -1, 0)) > 0.05
        assert moved.any()
        assert np.all(np.hypot(*np.moveaxis(s["deflection"], -1, 0))[moved] > 0)
        intr = s.meta["camera"]["intrinsics"]
        assert intr["cx"] == w / 2 and intr["fx"] == intr["fy"] > 0


def test_write_bos_writes_the_cli_dataset_and_resumes(tmp_path):
    cli_dataset(tmp_path / "cli", 6, 4)
    first = dataset.write_bos(tmp_path / "py", 6, seed=4, size=SIZE, indices=[0, 1, 2])
    assert first["rendered"] == 3 and not first["manifest"]
    rest = dataset.write_bos(tmp_path / "py", 6, seed=4, size=SIZE)
    assert rest["skipped"] == 3 and rest["rendered"] == 3 and rest["manifest"]
    same_folders(tmp_path / "cli", tmp_path / "py")
    assert dataset.shard(11, 0, 3) == [0, 1, 2, 3]
    assert sum((dataset.shard(11, i, 3) for i in range(3)), []) == list(range(11))
    with pytest.raises(grin.GrinError, match="not in a dataset of 6"):
        dataset.write_bos(tmp_path / "py", 6, seed=4, size=SIZE, indices=[6])


def test_ray_workers_write_the_single_process_dataset(tmp_path):
    ray = pytest.importorskip("ray")
    cli_dataset(tmp_path / "one", 24, 5)
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False,
             runtime_env={"env_vars": {"RAYON_NUM_THREADS": "1"}})
    try:
        @ray.remote(num_cpus=1)
        def shard_task(folder, i, n):
            from grin import dataset as d
            return d.write_bos(folder, 24, seed=5, size=SIZE, indices=d.shard(24, i, n))

        out = str(tmp_path / "ray")
        summaries = ray.get([shard_task.remote(out, i, 2) for i in range(2)])
    finally:
        ray.shutdown()
    assert sum(s["rendered"] for s in summaries) == 24
    # Whichever task ends last writes the manifest.
    if not (tmp_path / "ray" / "manifest.jsonl").exists():
        dataset.write_bos(tmp_path / "ray", 24, seed=5, size=SIZE)
    same_folders(tmp_path / "one", tmp_path / "ray")


@pytest.mark.parametrize("kind", ["schlieren", "haze"])
def test_schlieren_and_haze_samples_hold_their_images_and_truth(kind):
    (s,) = list(dataset.samples(kind, 1, seed=3, size=SIZE, media="expr"))
    h, w = SIZE[1], SIZE[0]
    assert s.meta["kind"] == kind and s.meta["medium"]["kind"] == "expr"
    assert s["deflection"].shape == (h, w, 2)
    if kind == "schlieren":
        assert s["schlieren"].shape == (h, w) and "displacement" not in s
    else:
        assert s["reference"].shape == (h, w, 3) and s["distorted"].shape == (h, w, 3)
        assert s["displacement"].shape == (h, w, 2)
        # The medium moves the background: the two images differ where it is.
        assert np.abs(s["distorted"] - s["reference"]).max() > 1e-3
    # The projected gradient over n is the deflection, for these weak media.
    np.testing.assert_allclose(s["deflection"], s["projected_gradient"] / 1.000272,
                               atol=0.03 * np.abs(s["deflection"]).max())
    with pytest.raises(grin.GrinError, match="unknown dataset kind `piv`"):
        next(dataset.samples("piv", 1))
    with pytest.raises(grin.GrinError, match="unknown media `smoke`"):
        next(dataset.samples(kind, 1, media="smoke"))


def test_haze_on_a_texture_wall(tmp_path):
    street = REPO / "data" / "images" / "street.png"
    (s,) = list(dataset.samples("haze", 1, seed=1, size=SIZE, textures=[street]))
    assert s.meta["background"]["kind"] == "texture"
    assert s["reference"].max() > 0.1  # the image is seen, lit by itself
    with pytest.raises(grin.GrinError, match="nope.png: no such image file"):
        next(dataset.samples("haze", 1, textures=[tmp_path / "nope.png"]))
