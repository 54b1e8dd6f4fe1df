"""grin for Python: gradient-index (GRIN) media rendered and traced into numpy arrays.

Scenes are grin's TOML scene files (docs/scene.md in the repository), loaded from a file,
a TOML string or a dict. Renders come back as a dict of float32 arrays named as the
channels of the EXR that ``grin render`` writes (``R``, ``G``, ``B``, ``aov.*``, or the
``[optics]`` mode's channels), bit for bit the same numbers on the same backend. Ray arrays
trace through the CPU tracer as ``grin trace`` does. Fields bake into and read from
``.grinf`` files as arrays, and a volume of your own (index, temperature or density)
becomes a baked field any scene can use (``field = { kind = "baked", path = ... }``).

grin releases the GIL while it renders, traces and bakes, so Python threads (and Ray
tasks) run grin side by side. Every error grin reports is raised as :class:`GrinError`
with grin's own message.
"""

from __future__ import annotations

import json
import os
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterator, Mapping, Optional, Sequence, Tuple, Union

import numpy as np

from . import _grin, dataset
from ._grin import GrinError, Renderer, Scene

__all__ = [
    "GrinError",
    "Scene",
    "Renderer",
    "Field",
    "SparseField",
    "Render",
    "load_scene",
    "render",
    "trace",
    "RAY_DTYPE",
    "STATUS_NAMES",
    "read_field",
    "bake",
    "bake_volume",
    "__version__",
    "dataset",
]

__version__: str = _grin.version()

PathLike = Union[str, "os.PathLike[str]"]

#: The ray statuses, indexed by the ``status`` column of :func:`trace`'s result.
STATUS_NAMES: Tuple[str, ...] = (
    "missed",
    "exited",
    "absorbed",
    "max_steps",
    "error",
    "degraded",
)

#: The columns of :func:`trace`'s result: those of ``grin trace``'s output table.
RAY_DTYPE = np.dtype(
    [
        ("status", "u1"),
        ("px", "f8"),
        ("py", "f8"),
        ("pz", "f8"),
        ("qx", "f8"),
        ("qy", "f8"),
        ("qz", "f8"),
        ("opl", "f8"),
        ("length", "f8"),
        ("steps", "u4"),
        ("evals", "u8"),
        ("error_estimate", "f8"),
    ]
)


def load_scene(
    source: Union[PathLike, Mapping[str, Any]],
    base_dir: Optional[PathLike] = None,
) -> Scene:
    """A scene from a TOML file's path, or from a dict of its tables.

    A dict's relative paths (a VDB file, a baked field) are resolved from ``base_dir``
    (default: the current directory); a file's from the file's own directory.
    """
    if isinstance(source, Mapping):
        return Scene.from_json(
            json.dumps(source), None if base_dir is None else os.fspath(base_dir)
        )
    return Scene.load(os.fspath(source))


class Render(dict):
    """A rendered scene: channel name -> float32 array of shape (height, width), row 0 at
    the top, as the EXR of ``grin render`` holds them. ``report`` is the render's summary
    (what ``grin render --json`` prints without the file names)."""

    report: dict

    def __init__(self, channels: Mapping[str, np.ndarray], report: dict):
        super().__init__(channels)
        self.report = report

    def rgb(self) -> np.ndarray:
        """The beauty image as (height, width, 3) float32 (beauty renders only)."""
        missing = [c for c in "RGB" if c not in self]
        if missing:
            raise KeyError(
                f"this render has no beauty channels (an [optics] output: {sorted(self)})"
            )
        return np.stack([self["R"], self["G"], self["B"]], axis=-1)


def render(
    scene: Union[Scene, PathLike, Mapping[str, Any]],
    backend: str = "cpu",
    *,
    renderer: Optional[Renderer] = None,
    width: Optional[int] = None,
    height: Optional[int] = None,
    spp: Optional[int] = None,
    frame: Optional[int] = None,
    fps: Optional[float] = None,
) -> Render:
    """Render a scene (a :class:`Scene`, a file path or a dict) to numpy channels.

    ``backend`` is ``"cpu"``, ``"gpu"`` (wgpu; Mesa's lavapipe on a machine without a
    GPU) or ``"auto"`` (the GPU where wgpu finds one, else the CPU; the report's
    ``backend`` and ``backend_note`` say which ran). Pass a :class:`Renderer` to keep its GPU device and pipelines across renders.
    ``width``, ``height`` and ``spp`` override the scene's ``[render]``; ``frame`` renders
    that frame of its sequence. Warnings grin reports are issued as ``RuntimeWarning``.
    """
    if not isinstance(scene, Scene):
        scene = load_scene(scene)
    if width is not None or height is not None or spp is not None:
        scene = scene.with_render(width, height, spp)
    if frame is not None:
        scene = scene.at_frame(frame, fps)
    if renderer is None:
        renderer = Renderer(backend)
    elif renderer.backend != backend and backend != "cpu":
        raise GrinError(
            f"renderer is on the {renderer.backend} backend, render asked for {backend}"
        )
    channels, report_json = renderer.render(scene)
    report = json.loads(report_json)
    for w in report.get("warnings", []):
        warnings.warn(f"grin: {w}", RuntimeWarning, stacklevel=2)
    return Render(channels, report)


def trace(
    scene: Union[Scene, PathLike, Mapping[str, Any]],
    rays: np.ndarray,
    *,
    integrator: Optional[str] = None,
    step: Optional[str] = None,
    max_steps: Optional[int] = None,
    f32: bool = False,
    summary: bool = False,
):
    """Trace rays through the scene's medium, as ``grin trace`` does.

    ``rays`` is an (N, 6) array of origin and direction (ox, oy, oz, dx, dy, dz). The
    result is a structured array of :data:`RAY_DTYPE` (exit point p, exit direction q,
    optical path, length, steps, evaluations, the ray's own error estimate in radians,
    and its status, an index into :data:`STATUS_NAMES`). ``integrator``, ``step``
    (``"fixed=0.01"``, ``"auto=1e-6"``, ...) and ``max_steps`` override the scene's, as
    the CLI's flags do; ``f32`` integrates in single precision as the GPU does. With
    ``summary=True`` the result is (array, summary dict).
    """
    if not isinstance(scene, Scene):
        scene = load_scene(scene)
    rays = np.ascontiguousarray(rays, dtype=np.float64)
    if rays.ndim != 2 or rays.shape[1] != 6:
        raise GrinError(
            f"rays must be an (N, 6) array of ox, oy, oz, dx, dy, dz; got shape {rays.shape}"
        )
    cols, summary_json = _grin.trace(scene, rays, integrator, step, max_steps, f32)
    for w in json.loads(summary_json).get("warnings", []):
        warnings.warn(f"grin: {w}", RuntimeWarning, stacklevel=2)
    out = np.empty(rays.shape[0], dtype=RAY_DTYPE)
    out["status"] = cols["status"]
    for i, axis in enumerate("xyz"):
        out["p" + axis] = cols["position"][:, i]
        out["q" + axis] = cols["direction"][:, i]
    for name in ("opl", "length", "steps", "evals", "error_estimate"):
        out[name] = cols[name]
    if summary:
        return out, json.loads(summary_json)
    return out


@dataclass
class Field:
    """A baked field: delta_n = n - ambient and grad n (per metre) at the grid's nodes.

    Arrays are indexed [k, j, i] (z, y, x; x fastest, as the file stores them); node
    (i, j, k) sits at ``origin + spacing * (i, j, k)`` in world metres.
    """

    delta_n: np.ndarray
    grad: np.ndarray
    info: dict
    report: Optional[dict] = field(default=None)

    @property
    def n(self) -> np.ndarray:
        """The index itself, ambient + delta_n (float64)."""
        return self.info["ambient"] + self.delta_n.astype(np.float64)

    @property
    def ambient(self) -> float:
        return self.info["ambient"]

    @property
    def origin(self) -> np.ndarray:
        return np.array(self.info["origin"])

    @property
    def spacing(self) -> np.ndarray:
        return np.array(self.info["spacing"])

    def node_coordinates(self) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
        """World x, y, z of the nodes along each axis."""
        nx, ny, nz = self.info["dims"]
        o, h = self.origin, self.spacing
        return (
            o[0] + h[0] * np.arange(nx),
            o[1] + h[1] * np.arange(ny),
            o[2] + h[2] * np.arange(nz),
        )


@dataclass(frozen=True)
class SparseField:
    """A sparse bake (``grin bake --sparse``): cubic bricks of a top grid, each active one
    with its own number of cells a side, delta_n = n - ambient and grad n (per metre) at its
    nodes; the rest of the box is exactly ambient.

    ``delta_n`` (N,) and ``grad`` (N, 3) hold every brick's nodes one brick after another;
    :meth:`bricks` cuts them into per-brick arrays indexed [k, j, i] (x fastest) with node
    (i, j, k) at ``origin + spacing * (i, j, k)`` in world metres. A tricubic
    (Catmull-Rom) bake, ``info["interp"] == "tricubic"``, stores ``info["apron"] == 1``
    more layer of nodes beyond each brick face: its arrays are ``cells + 3`` a side and
    their origin one spacing before the brick's corner.
    """

    delta_n: np.ndarray
    grad: np.ndarray
    brick_at: np.ndarray
    brick_cells: np.ndarray
    brick_offset: np.ndarray
    info: dict

    @property
    def ambient(self) -> float:
        return self.info["ambient"]

    def bricks(self) -> Iterator[Tuple[np.ndarray, float, np.ndarray, np.ndarray]]:
        """Each active brick: (origin, spacing, delta_n (m, m, m), grad (m, m, m, 3)),
        m = cells + 1 nodes a side (cells + 3 with an apron, the origin one spacing before
        the brick's corner)."""
        top = np.array(self.info["top_origin"])
        edge = self.info["brick_edge"]
        apron = int(self.info.get("apron", 0))
        for at, cells, first in zip(self.brick_at, self.brick_cells, self.brick_offset):
            m = int(cells) + 1 + 2 * apron
            end = int(first) + m**3
            spacing = edge / int(cells)
            yield (
                top + edge * at.astype(np.float64) - apron * spacing,
                spacing,
                self.delta_n[int(first):end].reshape(m, m, m),
                self.grad[int(first):end].reshape(m, m, m, 3),
            )


def read_field(path: PathLike) -> Union[Field, SparseField]:
    """Read a ``.grinf`` file (written by ``grin bake``, :func:`bake` or
    :func:`bake_volume`): a :class:`Field`, or a :class:`SparseField` for a sparse bake
    (``grin bake --sparse``)."""
    arrays, info = _grin.read_field(os.fspath(path))
    parsed = json.loads(info)
    if parsed.get("sparse"):
        return SparseField(
            arrays["delta_n"],
            arrays["grad"],
            arrays["brick_at"],
            arrays["brick_cells"],
            arrays["brick_offset"],
            parsed,
        )
    return Field(arrays["delta_n"], arrays["grad"], parsed)


def _baked(arrays: Mapping[str, Any], info: str, report: str) -> "Field":
    """A bake's result as a :class:`Field`; the field's warnings (a VDB grid its bounds
    cut, an expression's unproven positivity) are issued as ``RuntimeWarning``."""
    parsed = json.loads(report)
    for w in parsed.get("warnings", []):
        warnings.warn(f"grin: {w}", RuntimeWarning, stacklevel=3)
    return Field(arrays["delta_n"], arrays["grad"], json.loads(info), parsed)


def bake(
    scene: Union[Scene, PathLike, Mapping[str, Any]],
    path: Optional[PathLike] = None,
    *,
    resolution: Optional[int] = None,
    error_budget: Optional[float] = None,
    interp: str = "trilinear",
    max_memory: Optional[int] = None,
) -> Field:
    """Bake the scene's medium, as ``grin bake`` does: the coarsest grid that meets the
    error budget (or ``resolution`` nodes on the longest axis), cropped to where the index
    varies. Written to ``path`` (a ``.grinf``) when given, which may not be the scene file
    or a file the scene reads (``GrinError``)."""
    if not isinstance(scene, Scene):
        scene = load_scene(scene)
    arrays, info, report = _grin.bake(
        scene,
        None if path is None else os.fspath(path),
        resolution,
        error_budget,
        interp,
        max_memory,
    )
    return _baked(arrays, info, report)


#: Air's Gladstone-Dale constant (m^3/kg) and gas constant (J/(kg K)), as grin's VDB maps.
K_GD = 2.26e-4
R_AIR = 287.05
P_STANDARD = 101325.0


def bake_volume(
    values: np.ndarray,
    *,
    voxel_size: float,
    origin: Sequence[float] = (0.0, 0.0, 0.0),
    quantity: str = "index",
    k: Optional[float] = None,
    ambient: Optional[float] = None,
    ambient_temperature_k: float = 293.15,
    pressure_pa: float = P_STANDARD,
    bounds: Optional[Tuple[Sequence[float], Sequence[float]]] = None,
    path: Optional[PathLike] = None,
    resolution: Optional[int] = None,
    error_budget: Optional[float] = None,
    interp: str = "trilinear",
    max_memory: Optional[int] = None,
) -> Field:
    """Bake your own volume into a field (written to ``path`` when given).

    ``values`` is indexed [k, j, i] (z, y, x) at voxel centres ``origin + voxel_size *
    (i, j, k)`` (metres). ``quantity`` says what the values are:

    - ``"index"``: n itself (``ambient``, default 1.0, outside the volume);
    - ``"delta"``: n - ambient;
    - ``"linear"``: n = ambient + k * value;
    - ``"density"``: air density in kg/m^3, n = 1 + K_GD * rho (Gladstone-Dale);
    - ``"temperature"``: air temperature in kelvin at ``pressure_pa``, n = 1 + K_GD * P /
      (R_AIR * T) (``ambient_temperature_k`` outside the volume).

    The medium's bounds default to the volume's box; NaN or infinite values are refused.
    """
    values = np.ascontiguousarray(values, dtype=np.float32)
    if values.ndim != 3:
        raise GrinError(f"values must be a 3-D array (z, y, x); got shape {values.shape}")
    if quantity == "index":
        vdb_map = {"index": {"delta": False}}
        background = 1.0 if ambient is None else float(ambient)
    elif quantity == "delta":
        vdb_map = {"index": {"delta": True}}
        background = 0.0
    elif quantity == "linear":
        if k is None:
            raise GrinError('quantity "linear" needs k (n = ambient + k * value)')
        vdb_map = {"linear": {"k": float(k)}}
        background = 0.0
    elif quantity == "density":
        vdb_map = {"linear": {"k": K_GD if k is None else float(k)}}
        background = 0.0
        ambient = 1.0 if ambient is None else ambient
    elif quantity == "temperature":
        # The values as T - T_ambient: 0 outside the volume.
        values = values - np.float32(ambient_temperature_k)
        vdb_map = {
            "gladstone-dale": {
                "ambient_temperature_k": float(ambient_temperature_k),
                "scale_k": 1.0,
                "pressure_pa": float(pressure_pa),
                "k_gd": K_GD if k is None else float(k),
                "r_specific": R_AIR,
            }
        }
        background = 0.0
    else:
        raise GrinError(
            f"unknown quantity `{quantity}` (index, delta, linear, density or temperature)"
        )
    lo, hi = (None, None) if bounds is None else bounds
    arrays, info, report = _grin.bake_volume(
        values,
        float(voxel_size),
        [float(v) for v in origin],
        json.dumps(vdb_map),
        background,
        ambient,
        None if lo is None else [float(v) for v in lo],
        None if hi is None else [float(v) for v in hi],
        None if path is None else os.fspath(path),
        resolution,
        error_budget,
        interp,
        max_memory,
    )
    return _baked(arrays, info, report)
