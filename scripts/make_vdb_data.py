#!/usr/bin/python3
"""Generate grin's example and test OpenVDB files (data/vdb/) with Debian's python3-openvdb.

Run with the system interpreter (pyopenvdb is built for it):

    /usr/bin/python3 scripts/make_vdb_data.py            # writes data/vdb/

Deterministic: no randomness, so regenerating gives the same grids and values (the bytes
differ only by the random UUID OpenVDB writes into each file header).
Every grid whose values a test compares also gets a sidecar: `<file>.<grid>.f32`
(the values python asked OpenVDB to store, little-endian float32, x fastest, over the
grid's dense box) and one `<file>.json` describing boxes, transforms and expectations.
"""

import json
import math
import os
import sys

import numpy as np
import pyopenvdb as vdb

OUT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "data", "vdb")
TEST = os.path.join(OUT, "test")


def linear_transform(voxel_size, origin):
    """world = diag(voxel_size) * ijk + origin (OpenVDB matrices act on row vectors)."""
    sx, sy, sz = voxel_size
    return vdb.createLinearTransform(
        [[sx, 0, 0, 0], [0, sy, 0, 0], [0, 0, sz, 0], [origin[0], origin[1], origin[2], 1]]
    )


def float_grid(name, values_xyz, ijk0, voxel_size, origin, half=False, cls="fog volume"):
    g = vdb.FloatGrid()
    g.name = name
    g.copyFromArray(values_xyz.astype(np.float32), ijk=tuple(ijk0), tolerance=0)
    g.transform = linear_transform(voxel_size, origin)
    g.saveFloatAsHalf = half
    g.gridClass = cls
    return g


def sidecar(path, grid_name, values_xyz):
    """Dump values (indexed [i, j, k]) as float32, x fastest."""
    axes_zyx = (2, 1, 0) if values_xyz.ndim == 3 else (2, 1, 0, 3)
    arr = np.ascontiguousarray(values_xyz.astype("<f4").transpose(axes_zyx))
    arr.tofile(f"{path}.{grid_name}.f32")


def grid_record(name, values_xyz, ijk0, voxel_size, origin, half):
    dims = list(values_xyz.shape[:3])
    return {
        "grid": name,
        "dense_min": list(ijk0),
        "dense_dims": dims,
        "voxel_size": list(voxel_size),
        "origin": list(origin),
        "half_float": half,
    }


def axes(dims, ijk0, voxel_size, origin):
    """World coordinates of voxel centres along each axis."""
    return [origin[a] + voxel_size[a] * (ijk0[a] + np.arange(dims[a])) for a in range(3)]


def blender_cache():
    """A Mantaflow-like smoke/fire cache: density, temperature, flame as half floats,
    voxel size 0.05, origin offset below and to the side of the world origin."""
    dims = (24, 40, 24)
    h = (0.05, 0.05, 0.05)
    origin = (-0.6, -0.1, -0.6)
    ijk0 = (0, 0, 0)
    x, y, z = np.meshgrid(*axes(dims, ijk0, h, origin), indexing="ij")
    r2 = x * x + z * z
    # A plume rising from a burner at y = 0: widening with height, cooling as it rises.
    height = np.clip(y, 0.0, None)
    width = 0.12 + 0.25 * height
    # The burner's top at y = 0, smoothed over ~2 voxels: a hard cut would be a jump in
    # n that no interpolation (nor bake) resolves.
    base = 0.5 * (1.0 + np.tanh(y / 0.08))
    envelope = np.exp(-r2 / (width * width)) * base
    temperature = 2.0 * envelope * np.exp(-height / 1.2)
    flame = np.clip(1.0 - height / 0.35, 0.0, 1.0) * np.exp(-r2 / 0.01) * base
    density = 0.8 * envelope * (1.0 - np.exp(-height / 0.2))
    # Zero exactly where tiny so the grids are sparse (background 0, inactive).
    grids = []
    path = os.path.join(OUT, "blender_fire.vdb")
    records = []
    for name, vals in (("density", density), ("temperature", temperature), ("flame", flame)):
        vals = np.where(vals < 1e-4, 0.0, vals).astype(np.float32)
        g = float_grid(name, vals, ijk0, h, origin, half=True)
        g["blender/source"] = "grin make_vdb_data.py (Mantaflow-like)"
        grids.append(g)
        sidecar(path, name, vals)
        records.append(grid_record(name, vals, ijk0, h, origin, True))
    vdb.write(path, grids=grids, metadata={"creator": "Blender (grin example)", "frame": 42})
    return path, records


def houdini_cache():
    """A Houdini-like pyro cache: float temperature and vec3 vel, voxel size 0.1,
    negative index origin."""
    dims = (16, 20, 16)
    h = (0.1, 0.1, 0.1)
    origin = (0.0, 0.0, 0.0)
    ijk0 = (-8, -2, -8)
    x, y, z = np.meshgrid(*axes(dims, ijk0, h, origin), indexing="ij")
    r2 = x * x + z * z
    temperature = np.exp(-r2 / 0.16) * np.exp(-np.clip(y, 0, None) / 1.0) * (y >= 0)
    temperature = np.where(temperature < 1e-4, 0.0, temperature).astype(np.float32)
    vel = np.stack([-0.3 * x, 1.0 + 0.0 * y, -0.3 * z], axis=-1) * (temperature > 0)[..., None]
    vel = vel.astype(np.float32)
    path = os.path.join(OUT, "houdini_pyro.vdb")
    t = float_grid("temperature", temperature, ijk0, h, origin)
    v = vdb.Vec3SGrid()
    v.name = "vel"
    v.copyFromArray(vel, ijk=ijk0, tolerance=(0.0, 0.0, 0.0))
    v.transform = linear_transform(h, origin)
    v.vectorType = "contravariant relative"
    vdb.write(path, grids=[t, v], metadata={"creator": "Houdini (grin example)"})
    sidecar(path, "temperature", temperature)
    sidecar(path, "vel", vel)
    records = [grid_record("temperature", temperature, ijk0, h, origin, False)]
    rec = grid_record("vel", vel, ijk0, h, origin, False)
    rec["components"] = 3
    records.append(rec)
    return path, records


# Analytic field sampled into test/gaussian.vdb: delta_n = A exp(-|p - c|^2 / s^2).
GAUSS_A = 0.05
GAUSS_S = 0.25
GAUSS_C = (0.1, -0.05, 0.2)
GAUSS_H = 0.025
GAUSS_HALF_CELLS = 30


def gaussian():
    """delta_n of an analytic Gaussian on voxel centres, negative index origin."""
    n = 2 * GAUSS_HALF_CELLS + 1
    ijk0 = (-GAUSS_HALF_CELLS,) * 3
    h = (GAUSS_H,) * 3
    x, y, z = np.meshgrid(*axes((n, n, n), ijk0, h, GAUSS_C), indexing="ij")
    r2 = (x - GAUSS_C[0]) ** 2 + (y - GAUSS_C[1]) ** 2 + (z - GAUSS_C[2]) ** 2
    dn = (GAUSS_A * np.exp(-r2 / GAUSS_S**2)).astype(np.float32)
    path = os.path.join(TEST, "gaussian.vdb")
    g = float_grid("delta_n", dn, ijk0, h, GAUSS_C)
    vdb.write(path, grids=[g])
    return path, {
        "a": GAUSS_A,
        "s": GAUSS_S,
        "center": list(GAUSS_C),
        "voxel_size": GAUSS_H,
        "half_cells": GAUSS_HALF_CELLS,
    }


def anisotropic():
    """Small grid with non-uniform voxel sizes, negative origin, and a distinct value per
    voxel; both float and half-float copies."""
    dims = (5, 4, 3)
    ijk0 = (-3, -7, 2)
    h = (0.04, 0.05, 0.07)
    origin = (-1.25, 0.5, -0.75)
    i, j, k = np.meshgrid(*[np.arange(d) for d in dims], indexing="ij")
    vals = (1.0 + 0.1 * i + 0.01 * j + 0.001 * k + 1.0 / 3.0).astype(np.float32)
    path = os.path.join(TEST, "aniso.vdb")
    g = float_grid("value", vals, ijk0, h, origin)
    gh = float_grid("value_half", vals, ijk0, h, origin, half=True)
    vdb.write(path, grids=[g, gh], metadata={"purpose": "transform and value test"})
    sidecar(path, "value", vals)
    sidecar(path, "value_half", vals)
    return path, [
        grid_record("value", vals, ijk0, h, origin, False),
        grid_record("value_half", vals, ijk0, h, origin, True),
    ]


def bad_inputs():
    """Valid files that grin must refuse with a clear error."""
    out = {}
    # NaN and Inf voxels in an otherwise smooth temperature grid.
    dims = (8, 8, 8)
    vals = np.full(dims, 0.5, dtype=np.float32)
    vals[1, 2, 3] = np.nan
    vals[4, 4, 4] = np.inf
    vals[5, 1, 0] = -np.inf
    vals[7, 7, 7] = np.nan
    path = os.path.join(TEST, "nonfinite.vdb")
    g = float_grid("temperature", vals, (0, 0, 0), (0.1,) * 3, (0, 0, 0))
    # copyFromArray treats NaN as background (inactive): set the NaNs explicitly.
    acc = g.getAccessor()
    for ijk in ((1, 2, 3), (7, 7, 7)):
        acc.setValueOn(ijk, float("nan"))
    vdb.write(path, grids=[g])
    out["nonfinite"] = {"grid": "temperature", "non_finite": 4, "finite_value": 0.5}
    # A grid without active voxels.
    g = vdb.FloatGrid()
    g.name = "temperature"
    g.transform = linear_transform((0.1,) * 3, (0, 0, 0))
    vdb.write(os.path.join(TEST, "empty_grid.vdb"), grids=[g])
    # Two voxels far apart: tiny on disk, a dense box beyond any memory cap.
    g = vdb.FloatGrid()
    g.name = "temperature"
    acc = g.getAccessor()
    acc.setValueOn((0, 0, 0), 1.0)
    acc.setValueOn((60000, 60000, 60000), 1.0)
    g.transform = linear_transform((0.1,) * 3, (0, 0, 0))
    vdb.write(os.path.join(TEST, "huge_bbox.vdb"), grids=[g])
    # A frustum (non-linear) transform.
    vals = np.full((4, 4, 4), 0.25, dtype=np.float32)
    g = vdb.FloatGrid()
    g.name = "temperature"
    g.copyFromArray(vals, ijk=(0, 0, 0), tolerance=0)
    g.transform = vdb.createFrustumTransform((0, 0, 0), (3, 3, 3), 0.5, 2.0, 0.1)
    vdb.write(os.path.join(TEST, "frustum.vdb"), grids=[g])
    return out


def main():
    os.makedirs(TEST, exist_ok=True)
    manifest = {"generator": "scripts/make_vdb_data.py", "openvdb": list(vdb.LIBRARY_VERSION)}
    p, recs = blender_cache()
    manifest["blender_fire.vdb"] = recs
    p, recs = houdini_cache()
    manifest["houdini_pyro.vdb"] = recs
    p, recs = anisotropic()
    manifest["test/aniso.vdb"] = recs
    p, g = gaussian()
    manifest["test/gaussian.vdb"] = g
    manifest.update({f"test/{k}.vdb": v for k, v in bad_inputs().items()})
    with open(os.path.join(OUT, "manifest.json"), "w") as f:
        json.dump(manifest, f, indent=1, sort_keys=True)
        f.write("\n")
    for root, _, files in os.walk(OUT):
        for name in sorted(files):
            full = os.path.join(root, name)
            size = os.path.getsize(full)
            if size > 2 * 1024 * 1024:
                sys.exit(f"{full} is {size} bytes, over the 2 MB data budget")
            print(f"{os.path.relpath(full, OUT):40s} {size:9d} bytes")


if __name__ == "__main__":
    main()
