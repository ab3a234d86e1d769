from typing import Any, Optional, Sequence, Tuple, Union

import numpy as np
import numpy.typing as npt

SHIPPED_BY_QUALITY: Tuple[str, ...]

def denoise(
    color: npt.NDArray[np.float32],
    *,
    albedo: Optional[npt.NDArray[np.float32]] = ...,
    normal: Optional[npt.NDArray[np.float32]] = ...,
    position: Optional[npt.NDArray[np.float32]] = ...,
    depth: Optional[npt.NDArray[np.float32]] = ...,
    variance: Optional[npt.NDArray[np.float32]] = ...,
    spp: Optional[int] = ...,
    filter: Optional[str] = ...,
    pipeline: Optional[str] = ...,
    radius: Optional[int] = ...,
    point_sampled: bool = ...,
    motion: Optional[npt.NDArray[np.float32]] = ...,
    surface_normal: Optional[npt.NDArray[np.float32]] = ...,
) -> npt.NDArray[np.float32]: ...
class Denoiser:
    def __init__(
        self,
        filter: Optional[str] = ...,
        pipeline: Optional[str] = ...,
        radius: Optional[int] = ...,
        point_sampled: bool = ...,
    ) -> None: ...
    def denoise(
        self,
        color: npt.NDArray[np.float32],
        *,
        albedo: Optional[npt.NDArray[np.float32]] = ...,
        normal: Optional[npt.NDArray[np.float32]] = ...,
        position: Optional[npt.NDArray[np.float32]] = ...,
        depth: Optional[npt.NDArray[np.float32]] = ...,
        motion: Optional[npt.NDArray[np.float32]] = ...,
        variance: Optional[npt.NDArray[np.float32]] = ...,
        spp: Optional[int] = ...,
        surface_normal: Optional[npt.NDArray[np.float32]] = ...,
    ) -> npt.NDArray[np.float32]: ...
    def reset(self) -> None: ...
    @property
    def frames(self) -> int: ...
    @property
    def filter(self) -> Optional[str]: ...
    @property
    def pipeline(self) -> Optional[str]: ...

def choose(inputs: Sequence[str]) -> Tuple[str, str, str]: ...
def check(expr: str) -> dict[str, Any]: ...
def simplify(expr: str) -> str: ...
def compile(expr: str, pipeline: Optional[str] = ...) -> str: ...
def export(
    expr: str, target: str = ..., pipeline: Optional[str] = ..., format: str = ...
) -> Tuple[Union[str, bytes], dict[str, Any]]: ...
def relmse(image: npt.NDArray[np.float32], reference: npt.NDArray[np.float32]) -> float: ...
def flip(image: npt.NDArray[np.float32], reference: npt.NDArray[np.float32]) -> float: ...
def light(image: npt.NDArray[np.float32], reference: npt.NDArray[np.float32]) -> Optional[float]: ...
def device_name() -> str: ...
