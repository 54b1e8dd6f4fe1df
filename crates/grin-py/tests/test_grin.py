"""The Python package against the CLI (bit for bit), exact solutions and its own errors."""

import json
import os
import subprocess
import threading
import time
import warnings
import tomllib
from pathlib import Path

import numpy as np
import OpenEXR
import pytest

import grin

REPO = Path(__file__).resolve().parents[3]
SCENES = REPO / "data" / "scenes"
GRIN = Path(os.environ.get("GRIN_BIN", REPO / "target" / "debug" / "grin"))


def cli(*args):
    """Run the grin binary; fail with its stderr."""
    done = subprocess.run([str(GRIN), *map(str, args)], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    return done


def exr_channels(path):
    with OpenEXR.File(str(path), separate_channels=True) as f:
        return {name: ch.pixels for name, ch in f.channels().items()}


def assert_same_channels(numpy_render, exr):
    assert set(numpy_render) == set(exr)
    for name, array in numpy_render.items():
        assert array.dtype == np.float32
        assert array.shape == exr[name].shape, name
        # Bit for bit: the same float32 words (NaN where the EXR has NaN).
        assert np.array_equal(array.view(np.uint32), exr[name].view(np.uint32)), name


def test_render_equals_the_cli_exr_bit_for_bit_on_the_cpu(tmp_path):
    out = tmp_path / "hh.exr"
    cli("render", SCENES / "heat-haze.toml", "-o", out, "--backend", "cpu",
        "--size", "64x36", "--spp", "2")
    r = grin.render(SCENES / "heat-haze.toml", "cpu", width=64, height=36, spp=2)
    assert_same_channels(r, exr_channels(out))
    assert r.rgb().shape == (36, 64, 3)
    assert r.report["backend"] == "cpu"
    assert r.report["width"] == 64 and r.report["spp"] == 2


def test_optics_output_equals_the_cli_exr_bit_for_bit(tmp_path):
    scene = SCENES / "optics" / "bos.toml"
    out = tmp_path / "bos.exr"
    cli("render", scene, "-o", out, "--backend", "cpu", "--size", "48x32")
    r = grin.render(scene, "cpu", width=48, height=32)
    assert "displacement_px.X" in r and "reference" in r and "distorted" in r
    assert_same_channels(r, exr_channels(out))
    assert r.report["optics"]["mode"] == "bos"
    with pytest.raises(KeyError, match="no beauty channels"):
        r.rgb()


def test_gpu_render_equals_the_cli_exr_bit_for_bit(tmp_path):
    out = tmp_path / "a.exr"
    cli("render", SCENES / "paper-a.toml", "-o", out, "--backend", "gpu",
        "--size", "40x24", "--spp", "1", "--no-cache")
    renderer = grin.Renderer("gpu", cache=False)
    r = grin.render(SCENES / "paper-a.toml", "gpu", renderer=renderer, width=40,
                    height=24, spp=1)
    assert r.report["backend"] == "gpu"
    assert_same_channels(r, exr_channels(out))


def test_a_renderer_with_aovs_returns_those_channels_of_the_whole_render():
    for backend in ["cpu", "gpu"]:
        whole = grin.render(SCENES / "paper-a.toml", backend, width=40, height=24, spp=1,
                            renderer=grin.Renderer(backend, cache=False))
        some = grin.render(SCENES / "paper-a.toml", backend, width=40, height=24, spp=1,
                           renderer=grin.Renderer(backend, cache=False, aovs="steps,status"))
        assert sorted(some) == ["B", "G", "R", "aov.status", "aov.steps"]
        for name in some:
            np.testing.assert_array_equal(some[name], whole[name])
        assert some.report["status_counts"] == whole.report["status_counts"]
        assert some.report["steps_per_ray"] == whole.report["steps_per_ray"]
        if backend == "gpu":
            # 5 channels of 4 bytes in place of a pixel's 64, and 64 bytes of counts.
            saved = 40 * 24 * (64 - 20) - 64
            assert whole.report["read_back_bytes"] - some.report["read_back_bytes"] == saved
    with pytest.raises(grin.GrinError, match="unknown AOV `depth`"):
        grin.Renderer("cpu", aovs="depth")


def test_a_scene_from_a_dict_renders_as_its_file():
    with open(SCENES / "luneburg.toml", "rb") as f:
        tables = tomllib.load(f)
    from_dict = grin.render(grin.load_scene(tables, base_dir=SCENES), "cpu",
                            width=32, height=18, spp=1)
    from_file = grin.render(SCENES / "luneburg.toml", "cpu", width=32, height=18, spp=1)
    assert_same_channels(from_dict, from_file)


def test_luneburg_rays_leave_at_the_antipodal_point():
    # n^2 = 2 - r^2 (R = 1): a ray entering along d leaves at c + R d, along -(p - c)/R.
    rng = np.random.default_rng(7)
    n = 400
    d = np.array([0.0, 0.0, 1.0])
    xy = rng.uniform(-0.6, 0.6, size=(n, 2))
    rays = np.column_stack([xy, np.full(n, -3.0), np.tile(d, (n, 1))])
    out, summary = grin.trace(SCENES / "luneburg.toml", rays, integrator="rk4",
                              step="fixed=0.002", summary=True)
    assert summary["rays"] == n and summary["integrator"] == "rk4"
    assert out.dtype == grin.RAY_DTYPE
    assert np.all(out["status"] == grin.STATUS_NAMES.index("exited"))
    p = np.column_stack([out["px"], out["py"], out["pz"]])
    q = np.column_stack([out["qx"], out["qy"], out["qz"]])
    np.testing.assert_allclose(p, np.tile(d, (n, 1)), atol=1e-6)
    entry = np.column_stack([xy, -np.sqrt(1.0 - (xy**2).sum(axis=1))])
    np.testing.assert_allclose(q, -entry, atol=1e-6)


def test_trace_equals_the_cli_table(tmp_path):
    rng = np.random.default_rng(3)
    n = 300
    rays = np.column_stack([
        rng.uniform(-0.8, 0.8, n), rng.uniform(-0.8, 0.8, n), np.full(n, -3.0),
        rng.normal(0, 0.05, n), rng.normal(0, 0.05, n), np.ones(n),
    ])
    table = tmp_path / "rays.csv"
    np.savetxt(table, rays, delimiter=",", header="ox,oy,oz,dx,dy,dz", comments="",
               fmt="%.17g")
    cli("trace", SCENES / "luneburg.toml", "--rays", table, "-o", tmp_path / "out.csv")
    got = grin.trace(SCENES / "luneburg.toml", rays)
    with open(tmp_path / "out.csv") as f:
        header = f.readline().strip().split(",")
    rows = np.genfromtxt(tmp_path / "out.csv", delimiter=",", skip_header=1, dtype=str)
    col = {name: rows[:, i] for i, name in enumerate(header)}
    names = np.array(grin.STATUS_NAMES)[got["status"]]
    assert list(names) == list(col["status"])
    for name in ("px", "py", "pz", "qx", "qy", "qz", "opl", "length"):
        np.testing.assert_array_equal(got[name], col[name].astype(np.float64), err_msg=name)
    np.testing.assert_array_equal(got["steps"], col["steps"].astype(np.uint32))


@pytest.mark.parametrize("interp", ["trilinear", "tricubic"])
def test_read_field_reads_a_sparse_bake_brick_by_brick(tmp_path, interp):
    # data/scenes/plume.toml: n = ambient - sum a exp(-|r - c|^2 / s^2).
    path = tmp_path / "plume.grinf"
    cli("bake", SCENES / "plume.toml", "--sparse", "--interp", interp, "-o", path)
    read = grin.read_field(path)
    assert isinstance(read, grin.SparseField)
    info = read.info
    # A tricubic (Catmull-Rom) bake's bricks hold one layer of nodes beyond each face.
    apron = {"trilinear": 0, "tricubic": 1}[interp]
    assert (info["interp"], info["apron"]) == (interp, apron)
    active = len(read.brick_cells)
    assert 0 < active < int(np.prod(info["top_dims"]))
    last = int(read.brick_cells[-1]) + 1 + 2 * apron
    assert read.delta_n.shape == (int(read.brick_offset[-1]) + last ** 3,)
    plumes = [(6.0e-3, (0.0, 0.0, 3.5), 0.6), (5.0e-3, (-0.4, 0.3, 4.2), 0.4),
              (4.0e-3, (0.5, 0.2, 5.0), 0.5)]
    worst, worst_grad, nodes = 0.0, 0.0, 0
    for origin, spacing, delta, grad in read.bricks():
        m = delta.shape[0]
        assert delta.shape == (m, m, m) and grad.shape == (m, m, m, 3)
        k, j, i = np.meshgrid(*(np.arange(m),) * 3, indexing="ij")
        x, y, z = (origin[a] + spacing * c for a, c in enumerate((i, j, k)))
        gauss = [(a, c, s, np.exp(-((x - c[0]) ** 2 + (y - c[1]) ** 2 + (z - c[2]) ** 2) / s**2))
                 for a, c, s in plumes]
        exact = -sum(a * g for a, c, s, g in gauss)
        # grad n = sum 2 a (r - c) / s^2 exp(...).
        exact_grad = np.stack([sum(2 * a * (r - c[ax]) / s**2 * g for a, c, s, g in gauss)
                               for ax, r in enumerate((x, y, z))], axis=-1)
        # Nodes past the medium's box (bricks are cubes; no ray samples there) are not
        # the formula's.
        lo, hi = info["bounds_min"], info["bounds_max"]
        inside = ((x >= lo[0]) & (x <= hi[0]) & (y >= lo[1]) & (y <= hi[1])
                  & (z >= lo[2]) & (z <= hi[2]))
        if inside.any():
            worst = max(worst, float(np.abs(delta - exact)[inside].max()))
            worst_grad = max(worst_grad, float(np.abs(grad - exact_grad)[inside].max()))
        nodes += delta.size
    # Every brick's nodes hold the plumes' index (to the file's rounding, within the error
    # the bake measured between nodes).
    assert nodes == read.delta_n.size
    assert worst <= info["max_err_n"], (worst, info["max_err_n"])
    # The gradient is stored exact at the nodes (i16: to 1/32767 of the brick's largest).
    largest = float(np.abs(read.grad).max())
    assert worst_grad <= 1e-4 * largest, (worst_grad, largest)
    # A truncated sparse file is an error naming it.
    bad = tmp_path / "cut.grinf"
    bad.write_bytes(path.read_bytes()[:-100])
    with pytest.raises(grin.GrinError, match="cut.grinf"):
        grin.read_field(bad)


def test_bake_and_read_field_agree_with_the_profile(tmp_path):
    path = tmp_path / "lune.grinf"
    baked = grin.bake(SCENES / "luneburg.toml", path, resolution=33)
    assert baked.report["dims"] == baked.info["dims"]
    read = grin.read_field(path)
    np.testing.assert_array_equal(read.delta_n, baked.delta_n)
    np.testing.assert_array_equal(read.grad, baked.grad)
    nx, ny, nz = read.info["dims"]
    assert read.delta_n.shape == (nz, ny, nx) and read.grad.shape == (nz, ny, nx, 3)
    x, y, z = read.node_coordinates()
    zz, yy, xx = np.meshgrid(z, y, x, indexing="ij")
    r2 = xx**2 + yy**2 + zz**2
    inside = r2 < 0.9**2
    exact = np.sqrt(2.0 - r2[inside])
    # Nodes inside the lens hold its index to the file's quantisation.
    np.testing.assert_allclose(read.n[inside], exact, atol=2e-4)
    # d n / d x = -x / n, per metre.
    gx = read.grad[..., 0][inside]
    np.testing.assert_allclose(gx, -xx[inside] / exact, atol=5e-3)


def test_bake_never_replaces_what_the_scene_reads(tmp_path):
    # A bake onto its own scene file, or onto the .grinf its medium reads, is refused and
    # leaves the file as it was; once a call returns, its inputs are free to be written.
    scene = tmp_path / "lune.toml"
    scene.write_text((SCENES / "luneburg.toml").read_text())
    text = scene.read_bytes()
    with pytest.raises(grin.GrinError, match="an input of this run"):
        grin.bake(scene, scene, resolution=9)
    assert scene.read_bytes() == text
    grin.bake(scene, tmp_path / "b.grinf", resolution=9)
    baked_scene = tmp_path / "baked.toml"
    baked_scene.write_text(
        text.decode().replace('field = { kind = "luneburg" }',
                              'field = { kind = "baked", path = "b.grinf" }'))
    assert "b.grinf" in baked_scene.read_text()
    before = (tmp_path / "b.grinf").read_bytes()
    with pytest.raises(grin.GrinError, match="b.grinf"):
        grin.bake(baked_scene, tmp_path / "b.grinf", resolution=9)
    assert (tmp_path / "b.grinf").read_bytes() == before
    grin.bake(baked_scene, tmp_path / "c.grinf", resolution=9)
    # b.grinf was an input of the call before; now it may be written.
    grin.bake(scene, tmp_path / "b.grinf", resolution=11)
    assert (tmp_path / "b.grinf").read_bytes() != before


def test_a_temperature_volume_bakes_to_gladstone_dale_air(tmp_path):
    # A hot Gaussian plume in air at 293.15 K: n = 1 + K_GD P / (R T).
    h = 0.02
    k, j, i = np.meshgrid(np.arange(32), np.arange(32), np.arange(32), indexing="ij")
    r2 = ((i - 15.5) ** 2 + (j - 15.5) ** 2 + (k - 15.5) ** 2) * h * h
    temperature = 293.15 + 300.0 * np.exp(-r2 / 0.1**2)
    path = tmp_path / "plume.grinf"
    field = grin.bake_volume(temperature, voxel_size=h, quantity="temperature", path=path,
                             error_budget=1e-3)
    n_amb = 1.0 + grin.K_GD * grin.P_STANDARD / (grin.R_AIR * 293.15)
    assert field.ambient == pytest.approx(n_amb, abs=1e-9)
    n_data = 1.0 + grin.K_GD * grin.P_STANDARD / (grin.R_AIR * temperature)
    # The bake holds the data's index to its budget (relative to the largest change).
    change = n_amb - n_data.min()
    assert abs(field.n.min() - n_data.min()) <= 2e-3 * change
    assert field.n.max() == pytest.approx(n_amb, abs=1e-3 * change)
    assert field.report["meets_budget"]
    # A scene uses the baked volume as any baked field.
    scene = {
        "camera": {"position": [0.31, 0.31, -1.0], "look_at": [0.31, 0.31, 0.0],
                   "fov_y_deg": 20.0},
        "medium": {"bounds": {"box": {"min": [0, 0, 0], "max": [0.62, 0.62, 0.62]}},
                   "ambient_index": n_amb,
                   "field": {"kind": "baked", "path": "plume.grinf"}},
        "render": {"width": 16, "height": 16, "spp": 1},
    }
    r = grin.render(grin.load_scene(scene, base_dir=tmp_path), "cpu")
    status = r["aov.status"]
    assert np.count_nonzero(status == grin.STATUS_NAMES.index("exited")) > 0
    assert np.nanmax(r["aov.deflection_deg"]) > 0.0


def test_bad_input_raises_grin_errors_with_grins_message(tmp_path):
    with pytest.raises(grin.GrinError, match="nope.toml"):
        grin.load_scene(tmp_path / "nope.toml")
    with pytest.raises(grin.GrinError, match="unknown backend `tpu`"):
        grin.Renderer("tpu")
    with pytest.raises(grin.GrinError, match=r"\(N, 6\)"):
        grin.trace(SCENES / "luneburg.toml", np.zeros((4, 5)))
    with pytest.raises(grin.GrinError, match="unknown integrator"):
        grin.trace(SCENES / "luneburg.toml", np.zeros((4, 6)), integrator="magic")
    values = np.ones((8, 8, 8), dtype=np.float32)
    values[3, 4, 5] = np.nan
    with pytest.raises(grin.GrinError, match="(?i)non-finite|nan"):
        grin.bake_volume(values, voxel_size=0.1)
    with pytest.raises(grin.GrinError, match="voxel_size"):
        grin.bake_volume(np.ones((8, 8, 8)), voxel_size=-1.0)
    with pytest.raises(grin.GrinError, match="3-D"):
        grin.bake_volume(np.ones((8, 8)), voxel_size=0.1)
    bad = tmp_path / "bad.grinf"
    bad.write_bytes(b"GRINF\x00garbage")
    with pytest.raises(grin.GrinError, match="bad.grinf"):
        grin.read_field(bad)
    with pytest.raises(grin.GrinError, match=r"medium\.field\.n: must be > 0, got -1"):
        grin.load_scene({
            "camera": {"position": [0, 0, -3], "look_at": [0, 0, 0]},
            "medium": {"bounds": {"sphere": {"center": [0, 0, 0], "radius": 1.0}},
                       "field": {"kind": "uniform", "n": -1.0}},
        })


def test_the_gil_is_released_while_grin_renders():
    scene = grin.load_scene(SCENES / "heat-haze.toml").with_render(160, 90, 1)
    done = threading.Event()
    ticks = 0

    def work():
        grin.render(scene, "cpu")
        done.set()

    t = threading.Thread(target=work)
    t.start()
    while not done.is_set():
        ticks += 1
        time.sleep(0.001)
    t.join()
    # Python ran alongside the render: many ticks, not one at the end.
    assert ticks > 5


def test_a_volume_its_bounds_cut_bakes_with_a_warning():
    # Data in the voxels 2..5 of each axis (0.2 .. 0.5 m); bounds ending at 0.35 m in x
    # cut it: the bake goes on, and grin's warning arrives as a RuntimeWarning.
    values = np.zeros((8, 8, 8), dtype=np.float32)
    values[2:6, 2:6, 2:6] = 1e-3
    with pytest.warns(RuntimeWarning, match="bounds cut the grid's data"):
        field = grin.bake_volume(values, voxel_size=0.1, quantity="delta",
                                 bounds=((0.0, 0.0, 0.0), (0.35, 0.7, 0.7)), resolution=16)
    assert field.report["warnings"], field.report
    # Bounds that hold it all: no warning.
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        field = grin.bake_volume(values, voxel_size=0.1, quantity="delta", resolution=16)
    assert field.report["warnings"] == [], field.report


def test_a_trace_through_a_grid_its_bounds_cut_warns():
    # The test Gaussian (width 0.25 about (0.1, -0.05, 0.2)) in a sphere of radius 0.3
    # that cuts it: grin's warning arrives as a RuntimeWarning, and the rays are traced.
    tables = {
        "camera": {"position": [0.1, -0.05, -3.0], "look_at": [0.1, -0.05, 0.2]},
        "medium": {
            "bounds": {"sphere": {"center": [0.1, -0.05, 0.2], "radius": 0.3}},
            "field": {"kind": "vdb", "path": str(REPO / "data" / "vdb" / "test" / "gaussian.vdb"),
                      "grid": "delta_n", "map": {"index": {"delta": True}}},
        },
    }
    rays = np.array([[0.1, -0.05, -1.0, 0.0, 0.0, 1.0]])
    with pytest.warns(RuntimeWarning, match="bounds cut the grid's data"):
        out = grin.trace(grin.load_scene(tables, base_dir=REPO), rays)
    assert out["status"][0] == 1, out
