"""The fleet examples of docs/scale.md, run in the form this machine allows; and VDB
files from Python, through the crash-isolating checker."""

import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import grin

REPO = Path(__file__).resolve().parents[3]
GRIN = Path(os.environ.get("GRIN_BIN", REPO / "target" / "debug" / "grin")).resolve()
EXAMPLES = REPO / "scripts" / "scale"


def test_the_slurm_array_script_writes_one_dataset_from_its_tasks(tmp_path):
    out = tmp_path / "slurm"
    env = {**os.environ, "GRIN": str(GRIN), "OUT": str(out), "COUNT": "8", "SIZE": "32x24"}
    tasks = [
        subprocess.Popen(["bash", str(EXAMPLES / "slurm_bos.sh")],
                         env={**env, "SLURM_ARRAY_TASK_ID": str(i),
                              "SLURM_ARRAY_TASK_COUNT": "2"},
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        for i in range(2)
    ]
    for t in tasks:
        stdout, stderr = t.communicate()
        assert t.returncode == 0, stderr
        assert "4 samples rendered" in stdout
    # A requeued task finds its samples complete, and writes the manifest.
    redo = subprocess.run(["bash", str(EXAMPLES / "slurm_bos.sh")],
                          env={**env, "SLURM_ARRAY_TASK_ID": "1",
                               "SLURM_ARRAY_TASK_COUNT": "2"},
                          capture_output=True, text=True)
    assert redo.returncode == 0, redo.stderr
    assert "0 samples rendered, 4 skipped" in redo.stdout
    assert len((out / "manifest.jsonl").read_text().splitlines()) == 8
    # Outside Slurm the script says what it misses.
    bare = subprocess.run(["bash", str(EXAMPLES / "slurm_bos.sh")], env=env,
                          capture_output=True, text=True)
    assert bare.returncode != 0 and "not a Slurm array task" in bare.stderr


def test_the_openjd_template_renders_and_resumes(tmp_path):
    openjd = shutil.which("openjd", path=os.path.dirname(sys.executable)) or shutil.which(
        "openjd")
    if openjd is None:
        pytest.skip("openjd-cli is not installed (scripts/python.sh installs it)")
    out = tmp_path / "frames"
    out.mkdir()
    args = [openjd, "run", str(EXAMPLES / "openjd_render.yaml"), "--step", "Render",
            "-p", f"Scene={REPO / 'data' / 'scenes' / 'noise-sphere.toml'}",
            "-p", f"Output={out / 'noise.####.exr'}", "-p", "Frames=1-3:2,4",
            "-p", f"Grin={GRIN}", "-p", "Size=32x18"]
    first = subprocess.run(args, capture_output=True, text=True)
    assert first.returncode == 0, first.stdout + first.stderr
    assert sorted(p.name for p in out.glob("*.exr")) == [
        "noise.0001.exr", "noise.0003.exr", "noise.0004.exr"]
    again = subprocess.run(args, capture_output=True, text=True)
    assert again.returncode == 0
    assert again.stdout.count("skipped frame") == 3


def test_a_vdb_scene_traces_from_python():
    rays = np.array([[0.0, 0.5, -3.0, 0.0, 0.0, 1.0]] * 4)
    out, summary = grin.trace(REPO / "data" / "vdb" / "fire-haze.toml", rays, summary=True)
    assert "blender_fire.vdb:temperature" in summary["field"]
    assert np.all(out["status"] == grin.STATUS_NAMES.index("exited"))


@pytest.mark.parametrize("name", ["crash_abort.vdb", "truncated"])
def test_a_bad_vdb_file_is_a_grin_error_not_a_crash(tmp_path, name):
    test_data = REPO / "data" / "vdb" / "test"
    if name == "truncated":
        bad = tmp_path / "truncated.vdb"
        bad.write_bytes((test_data / "gaussian.vdb").read_bytes()[:300])
    else:
        bad = test_data / name
    scene = {
        "camera": {"position": [0, 0, -3], "look_at": [0, 0, 0]},
        "medium": {"bounds": {"box": {"min": [-1, -1, -1], "max": [1, 1, 1]}},
                   "field": {"kind": "vdb", "path": str(bad), "grid": "density",
                             "map": {"index": {"delta": True}}}},
    }
    with pytest.raises(grin.GrinError, match=bad.name):
        grin.trace(grin.load_scene(scene, base_dir=tmp_path), np.zeros((1, 6)))
