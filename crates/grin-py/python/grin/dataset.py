"""Datasets for learning, as ``grin dataset`` makes them: image pairs of randomised media
with their ground truth, deterministic by seed and sample index (sample ``i`` depends on
``(seed, i)`` alone).

Kinds: ``"bos"`` (a random-dot plate without and with the medium), ``"schlieren"`` (a
knife-edge image) and ``"haze"`` (a background, a checker wall, a texture image on it or a plate image,
without and with the medium, with its ST map). Media: ``"plumes"``, ``"noise"``, ``"expr"`` or
``"scene:PATH"`` (a scene file's ``[medium]`` at a random frame of its ``[animation]``: a
pool of VDB frames).

:func:`samples` yields samples in memory; :func:`write` writes them to a folder exactly as
``grin dataset`` does (the same files, byte for byte), skipping complete samples, so that
shards (:func:`shard`) run in separate processes, on Ray workers or Slurm array tasks, and
retries, add up to one dataset. :func:`bos` and :func:`write_bos` are the BOS shortcuts.
"""

from __future__ import annotations

import json
import os
from typing import Any, Dict, Iterator, List, Optional, Sequence, Tuple

import numpy as np

from . import _grin
from ._grin import GrinError, Renderer

__all__ = ["samples", "write", "bos", "write_bos", "shard", "Sample"]


class Sample(dict):
    """One sample: arrays by name, and ``meta`` (its JSON: seeds, medium, camera
    intrinsics and extrinsics, background, the scene TOML).

    - ``reference``, ``distorted``: the two images, (height, width) float32 in [0, 1] for
      BOS (the two exposures), (height, width, 3) linear RGB for haze;
    - ``schlieren``: the schlieren image (schlieren samples);
    - ``displacement``: the true displacement in pixels, (height, width, 2) (x right,
      y down), and ``valid``, where it is defined (bos, haze);
    - ``deflection``: each pixel ray's deflection in radians along the camera's right and
      up, (height, width, 2);
    - ``projected_gradient``: grad n integrated along each pixel's undeflected ray, the
      same axes (deflection ~ it / n for small angles);
    - ``slice``: the medium's index on the plane through its centre facing the camera,
      (64, 64), row 0 at the top;
    - ``channels``: every channel of the sample's EXR by its name.
    """

    meta: dict


def _sample(channels: Dict[str, np.ndarray], meta: dict) -> Sample:
    s = Sample(slice=channels["slice.n"],
               channels={k: v for k, v in channels.items() if k != "slice.n"})
    kind = meta["kind"]
    if kind == "bos":
        s["reference"], s["distorted"] = channels["reference"], channels["distorted"]
    elif kind == "haze":
        for name in ("reference", "distorted"):
            s[name] = np.stack([channels[f"{name}.{c}"] for c in "RGB"], axis=-1)
    else:
        s["schlieren"] = channels["schlieren"]
    if "displacement_px.X" in channels:
        s["displacement"] = np.stack(
            [channels["displacement_px.X"], channels["displacement_px.Y"]], axis=-1)
        s["valid"] = channels["valid"] > 0.5
    s["deflection"] = np.stack(
        [channels["deflection_rad.X"], channels["deflection_rad.Y"]], axis=-1)
    s["projected_gradient"] = np.stack(
        [channels["grad_n_line.X"], channels["grad_n_line.Y"]], axis=-1)
    s.meta = meta
    return s


def shard(count: int, index: int, shards: int) -> List[int]:
    """The sample indices of shard ``index`` of ``shards`` (0-based): contiguous ranges
    of as equal size as can be, as ``grin dataset --shard I/N`` takes them."""
    if shards < 1 or not 0 <= index < shards:
        raise GrinError(f"shard {index}/{shards}: the index must be below the count")
    base, extra = divmod(count, shards)
    start = index * base + min(index, extra)
    return list(range(start, start + base + (1 if index < extra else 0)))


def samples(
    kind: str,
    count: int,
    seed: int = 0,
    size: Tuple[int, int] = (128, 96),
    media: str = "plumes",
    plates: Sequence["os.PathLike[str] | str"] = (),
    textures: Sequence["os.PathLike[str] | str"] = (),
    backend: str = "cpu",
    start: int = 0,
    renderer: Optional[Renderer] = None,
) -> Iterator[Sample]:
    """Yield samples ``start .. start + count - 1`` of the ``kind`` dataset ``seed``."""
    renderer = renderer or Renderer(backend)
    width, height = size
    plates = [os.fspath(p) for p in plates]
    for i in range(start, start + count):
        channels, meta = _grin.dataset_sample(
            renderer, kind, media, plates, [os.fspath(t) for t in textures], i, seed, width,
            height)
        yield _sample(channels, json.loads(meta))


def write(
    folder: "os.PathLike[str] | str",
    kind: str,
    count: int,
    seed: int = 0,
    size: Tuple[int, int] = (128, 96),
    media: str = "plumes",
    plates: Sequence["os.PathLike[str] | str"] = (),
    textures: Sequence["os.PathLike[str] | str"] = (),
    backend: str = "cpu",
    indices: Optional[List[int]] = None,
    renderer: Optional[Renderer] = None,
) -> Dict[str, Any]:
    """Write samples (default: all ``count``; else ``indices``, e.g. :func:`shard`'s) of
    the ``kind`` dataset ``seed`` to ``folder``, skipping complete ones. Returns the run's
    summary (rendered, skipped, seconds, samples_per_second, manifest)."""
    renderer = renderer or Renderer(backend)
    width, height = size
    todo = list(range(count)) if indices is None else [int(i) for i in indices]
    return json.loads(_grin.dataset_write(
        renderer, kind, media, [os.fspath(p) for p in plates],
        [os.fspath(t) for t in textures], os.fspath(folder), count, todo, seed, width, height))


def bos(count: int, seed: int = 0, size: Tuple[int, int] = (128, 96), **kw) -> Iterator[Sample]:
    """:func:`samples` of kind ``"bos"``."""
    return samples("bos", count, seed, size, **kw)


def write_bos(folder, count: int, seed: int = 0, size: Tuple[int, int] = (128, 96), **kw):
    """:func:`write` of kind ``"bos"``."""
    return write(folder, "bos", count, seed, size, **kw)
