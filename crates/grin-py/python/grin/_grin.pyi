"""Type stubs of grin's native module (crates/grin-py/src/lib.rs). Use the ``grin``
package's functions; these are what they call."""

from os import PathLike
from typing import Dict, Optional, Sequence, Tuple, Union

import numpy as np
import numpy.typing as npt

_Path = Union[str, PathLike[str]]

class GrinError(Exception): ...

class Scene:
    @staticmethod
    def load(path: _Path) -> Scene: ...
    @staticmethod
    def from_toml(
        text: str, base_dir: Optional[_Path] = None, name: Optional[str] = None
    ) -> Scene: ...
    @staticmethod
    def from_json(
        text: str, base_dir: Optional[_Path] = None, name: Optional[str] = None
    ) -> Scene: ...
    def with_render(
        self,
        width: Optional[int] = None,
        height: Optional[int] = None,
        spp: Optional[int] = None,
    ) -> Scene: ...
    def at_frame(self, frame: int, fps: Optional[float] = None) -> Scene: ...
    @property
    def width(self) -> int: ...
    @property
    def height(self) -> int: ...
    @property
    def spp(self) -> int: ...
    @property
    def name(self) -> str: ...
    @property
    def optics(self) -> Optional[str]: ...

class Renderer:
    def __init__(self, backend: str = "cpu", cache: bool = True, aovs: str = "all") -> None: ...
    @property
    def backend(self) -> str: ...
    def render(self, scene: Scene) -> Tuple[Dict[str, npt.NDArray[np.float32]], str]: ...

def trace(
    scene: Scene,
    rays: npt.NDArray[np.float64],
    integrator: Optional[str] = None,
    step: Optional[str] = None,
    max_steps: Optional[int] = None,
    f32: bool = False,
) -> Tuple[Dict[str, np.ndarray], str]: ...
def read_field(path: _Path) -> Tuple[Dict[str, np.ndarray], str]: ...
def bake(
    scene: Scene,
    path: Optional[_Path] = None,
    resolution: Optional[int] = None,
    error_budget: Optional[float] = None,
    interp: str = "trilinear",
    max_memory: Optional[int] = None,
) -> Tuple[Dict[str, npt.NDArray[np.float32]], str, str]: ...
def bake_volume(
    values: npt.NDArray[np.float32],
    voxel_size: float,
    origin: Sequence[float],
    map_json: str,
    background: float,
    ambient: Optional[float] = None,
    bounds_min: Optional[Sequence[float]] = None,
    bounds_max: Optional[Sequence[float]] = None,
    path: Optional[_Path] = None,
    resolution: Optional[int] = None,
    error_budget: Optional[float] = None,
    interp: str = "trilinear",
    max_memory: Optional[int] = None,
) -> Tuple[Dict[str, npt.NDArray[np.float32]], str, str]: ...
def version() -> str: ...
def version() -> str: ...
def dataset_bos_sample(
    renderer: Renderer, index: int, seed: int, width: int, height: int
) -> Tuple[Dict[str, npt.NDArray[np.float32]], str]: ...
def dataset_bos_write(
    renderer: Renderer,
    dir: _Path,
    count: int,
    indices: Sequence[int],
    seed: int,
    width: int,
    height: int,
) -> str: ...
def dataset_sample(
    renderer: Renderer,
    kind: str,
    media: str,
    plates: Sequence[_Path],
    textures: Sequence[_Path],
    index: int,
    seed: int,
    width: int,
    height: int,
) -> Tuple[Dict[str, npt.NDArray[np.float32]], str]: ...
def dataset_write(
    renderer: Renderer,
    kind: str,
    media: str,
    plates: Sequence[_Path],
    textures: Sequence[_Path],
    dir: _Path,
    count: int,
    indices: Sequence[int],
    seed: int,
    width: int,
    height: int,
) -> str: ...
