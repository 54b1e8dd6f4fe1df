"""Datasets for learning, as ``grin dataset`` makes them: background-oriented schlieren
(BOS) pairs of randomised hot-air plumes with their ground truth, deterministic by seed
and sample index (sample ``i`` depends on ``(seed, i)`` alone).

:func:`bos` yields samples in memory; :func:`write_bos` writes them to a folder exactly as
``grin dataset bos`` does (the same files, byte for byte), skipping complete samples, so
that shards (:func:`shard`) run in separate processes, on Ray workers or Slurm array
tasks, and retries, add up to one dataset.
"""

from __future__ import annotations

import json
import os
from typing import Any, Dict, Iterator, List, Optional, Tuple

import numpy as np

from . import _grin
from ._grin import GrinError, Renderer

__all__ = ["bos", "write_bos", "shard", "Sample"]


class Sample(dict):
    """One BOS sample: arrays by name, and ``meta`` (its JSON: seeds, medium, camera
    intrinsics and extrinsics, plate, the scene TOML).

    - ``reference``, ``distorted``: the two exposures, (height, width) float32 in [0, 1];
    - ``displacement``: the true displacement in pixels, (height, width, 2) (x right,
      y down); ``valid``: where it is defined;
    - ``deflection``: each pixel ray's deflection in radians, (height, width, 2);
    - ``slice``: the medium's index on its mid-plane z = 0, (64, 64), row 0 at the top;
    - ``channels``: every channel of the sample's EXR by its name.
    """

    meta: dict


def _sample(channels: Dict[str, np.ndarray], meta: dict) -> Sample:
    s = Sample(
        reference=channels["reference"],
        distorted=channels["distorted"],
        displacement=np.stack(
            [channels["displacement_px.X"], channels["displacement_px.Y"]], axis=-1
        ),
        valid=channels["valid"] > 0.5,
        deflection=np.stack(
            [channels["deflection_rad.X"], channels["deflection_rad.Y"]], axis=-1
        ),
        slice=channels["slice.n"],
        channels={k: v for k, v in channels.items() if k != "slice.n"},
    )
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


def bos(
    count: int,
    seed: int = 0,
    size: Tuple[int, int] = (128, 96),
    backend: str = "cpu",
    start: int = 0,
    renderer: Optional[Renderer] = None,
) -> Iterator[Sample]:
    """Yield samples ``start .. start + count - 1`` of the BOS dataset ``seed``."""
    renderer = renderer or Renderer(backend)
    width, height = size
    for i in range(start, start + count):
        channels, meta = _grin.dataset_bos_sample(renderer, i, seed, width, height)
        yield _sample(channels, json.loads(meta))


def write_bos(
    folder: "os.PathLike[str] | str",
    count: int,
    seed: int = 0,
    size: Tuple[int, int] = (128, 96),
    backend: str = "cpu",
    indices: Optional[List[int]] = None,
    renderer: Optional[Renderer] = None,
) -> Dict[str, Any]:
    """Write samples (default: all ``count``; else ``indices``, e.g. :func:`shard`'s) of
    the BOS dataset ``seed`` to ``folder``, skipping complete ones. Returns the run's
    summary (rendered, skipped, seconds, samples_per_second, manifest)."""
    renderer = renderer or Renderer(backend)
    width, height = size
    todo = list(range(count)) if indices is None else [int(i) for i in indices]
    return json.loads(
        _grin.dataset_bos_write(
            renderer, os.fspath(folder), count, todo, seed, width, height
        )
    )
