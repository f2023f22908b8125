"""Type stubs of the extension module ``ellipso._native`` (python/src). Use the package's
public names (``ellipso.polar``, ``ellipso.Session`` …); these are their native bodies."""

import os
from typing import Any, Callable, Dict, List, Optional, Tuple, Union

import numpy as np
import numpy.typing as npt

__version__: str

class EllipsoError(RuntimeError):
    """A failure inside ellipso; the message is the command line's."""

_Path = Union[str, os.PathLike[str]]
_Progress = Optional[Callable[[str, str], Any]]
_F64 = npt.NDArray[np.float64]

class Session:
    def __init__(self, path: _Path) -> None: ...
    @property
    def path(self) -> str: ...
    @property
    def layout(self) -> str: ...
    @property
    def width(self) -> int: ...
    @property
    def height(self) -> int: ...
    @property
    def bit_depth(self) -> int: ...
    @property
    def frame_ids(self) -> npt.NDArray[np.uint64]: ...
    @property
    def read_report(self) -> str: ...
    @property
    def manifest(self) -> Dict[str, Any]: ...
    @property
    def events(self) -> List[Dict[str, Any]]: ...
    @property
    def frame_records(self) -> List[Dict[str, Any]]: ...
    @property
    def rig(self) -> Optional[Dict[str, Any]]: ...
    @property
    def camera(self) -> Optional[Dict[str, float]]: ...
    def frame(self, frame_id: int) -> npt.NDArray[np.uint16]: ...
    def tracked_poses(self) -> Tuple[npt.NDArray[np.uint64], _F64]: ...
    def interpolated_poses(self) -> Tuple[npt.NDArray[np.uint64], _F64]: ...
    def rejected_poses(self) -> Dict[int, str]: ...

def polar(
    mosaic: np.ndarray,
    *,
    layout: Optional[str] = None,
    bit_depth: Optional[int] = None,
    demosaic: str = "superpixel",
    dark_level: float = 0.0,
    saturation: Optional[int] = None,
    dark_intensity: float = 0.001,
    max_residual: Optional[float] = None,
) -> Dict[str, Any]: ...
def _bench_polar_rust(
    mosaic: np.ndarray, repeats: int, *, layout: str, demosaic: str = "superpixel"
) -> List[float]: ...
def mueller(
    eta: _F64, sigma_s: _F64, sigma_ss: _F64, rho_s: _F64, rho_ss: _F64, rho_d: _F64,
    normal: _F64, to_light: _F64, to_camera: _F64, light_up: _F64, camera_up: _F64,
) -> Dict[str, np.ndarray]: ...
def coaxial(
    eta: _F64, sigma_s: _F64, sigma_ss: _F64, rho_s: _F64, rho_ss: _F64, rho_d: _F64,
    normal_camera: _F64,
) -> _F64: ...
def fresnel(eta: _F64, theta_deg: _F64) -> Dict[str, _F64]: ...
def mesh(
    session: _Path, out: _Path, *, vertices: int = 2500, progress: _Progress = None
) -> Dict[str, Any]: ...
def fit(
    session: _Path,
    out: _Path,
    *,
    mesh: Optional[_Path] = None,
    vertices: int = 2500,
    outer: Optional[int] = None,
    holdout: float = 0.1,
    joint_only: bool = False,
    normal_prior_deg: float = 10.0,
    grazing_cutoff_deg: float = ...,
    view: Optional[int] = None,
    no_hull: bool = False,
    progress: _Progress = None,
) -> Dict[str, Any]: ...
def fit_flag_names() -> List[str]: ...
