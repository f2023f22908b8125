"""A recorded session, read-only: ``ellipso.Session(path)``."""

from __future__ import annotations

import os
from dataclasses import dataclass
from typing import Any, Dict, List, Optional, Union

import numpy as np

from . import _native


@dataclass(frozen=True)
class Camera:
    """The camera model of the session's rig record (full raw resolution, pixels).

    ``distortion`` is OpenCV's ``(k1, k2, p1, p2, k3)`` (Brown–Conrady on normalised
    coordinates), so ``cv2.undistort(image, camera.K, camera.distortion)`` applies as is.
    """

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float
    k1: float
    k2: float
    k3: float
    p1: float
    p2: float

    @property
    def K(self) -> np.ndarray:
        """The 3×3 intrinsic matrix (px)."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    @property
    def distortion(self) -> np.ndarray:
        """OpenCV's distortion vector ``(k1, k2, p1, p2, k3)``."""
        return np.array([self.k1, self.k2, self.p1, self.p2, self.k3])


@dataclass(frozen=True)
class Poses:
    """Camera poses by frame: ``world_from_camera[k]`` maps frame ``frame_ids[k]``'s camera
    coordinates (OpenCV axes: x right, y down, z forward; metres) to the world, the board
    frame of the capture (metres). Both arrays are read-only."""

    frame_ids: np.ndarray
    world_from_camera: np.ndarray

    #: The frames the 4×4 matrices map between: camera → world.
    frame: str = "world_from_camera"

    def __len__(self) -> int:
        return len(self.frame_ids)

    def __getitem__(self, frame_id: int) -> np.ndarray:
        """The 4×4 ``world_from_camera`` of frame ``frame_id``."""
        hits = np.flatnonzero(self.frame_ids == frame_id)
        if len(hits) == 0:
            raise KeyError(f"no pose for frame {frame_id}")
        return self.world_from_camera[hits[0]]

    def camera_from_world(self) -> np.ndarray:
        """The inverses, ``(n, 4, 4)``: world → camera."""
        return np.linalg.inv(self.world_from_camera)


@dataclass(frozen=True)
class FrameRecord:
    """One frame of the session as its log describes it."""

    frame_id: int
    #: False when the frame was flagged incomplete at capture.
    complete: bool
    #: The flash pulse it was paired with, if any.
    pulse_seq: Optional[int]
    #: The flash-energy bracket step of its pulse (0 without a bracket).
    bracket_step: int
    #: The pulse's actual flash on-time, µs, where recorded.
    flash_on_us: Optional[int]
    #: Flash energy relative to the capture's full pulse (1.0 when not recorded).
    flash_energy_rel: float
    #: The frame's PNG.
    file: str


def _readonly(a: np.ndarray) -> np.ndarray:
    a.setflags(write=False)
    return a


class Session:
    """A recorded session (``docs/session-format.md``), opened read-only.

    ``Session(path)`` reads the manifest and the event log once, as every ``ellipso`` command
    does; frames are decoded when asked for. Nothing in the session is ever written.

    :raises FileNotFoundError: no session (no ``manifest.json``) at ``path``.
    :raises ValueError: an unreadable manifest (the message names file, line and column).
    """

    def __init__(self, path: Union[str, "os.PathLike[str]"]) -> None:
        self._native = _native.Session(os.fspath(path))

    def __repr__(self) -> str:
        return repr(self._native)

    @property
    def path(self) -> str:
        """The session folder."""
        return os.fspath(self._native.path)

    @property
    def layout(self) -> str:
        """``'mono'`` (IMX250MZR) or ``'colour'`` (IMX250MYR): pass it to :func:`ellipso.polar`."""
        return self._native.layout

    @property
    def width(self) -> int:
        """Frame width, px."""
        return self._native.width

    @property
    def height(self) -> int:
        """Frame height, px."""
        return self._native.height

    @property
    def bit_depth(self) -> int:
        """Significant bits per sample of the frames (in their 16-bit container)."""
        return self._native.bit_depth

    @property
    def frame_ids(self) -> np.ndarray:
        """Ids of the frames on disk, ascending (``uint64``)."""
        return _readonly(self._native.frame_ids)

    def __len__(self) -> int:
        return len(self._native.frame_ids)

    def frame(self, frame_id: int) -> np.ndarray:
        """The raw mosaic of frame ``frame_id`` as recorded: ``uint16``, ``(height, width)``,
        right-aligned DN (``bit_depth`` significant bits).

        :raises KeyError: the session has no such frame.
        :raises ValueError: the frame file is corrupt or not the manifest's size.
        """
        return self._native.frame(int(frame_id))

    @property
    def frames(self) -> List[FrameRecord]:
        """Every frame on disk with what the log says of it."""
        return [
            FrameRecord(**{**r, "file": os.fspath(r["file"])})
            for r in self._native.frame_records
        ]

    @property
    def poses(self) -> Poses:
        """The tracked poses (the log's last word per frame), camera → world."""
        ids, m = self._native.tracked_poses()
        return Poses(_readonly(ids), _readonly(m))

    @property
    def interpolated_poses(self) -> Poses:
        """Poses borrowed by short-pulse frames from their tracked neighbours."""
        ids, m = self._native.interpolated_poses()
        return Poses(_readonly(ids), _readonly(m))

    @property
    def rejected_poses(self) -> Dict[int, str]:
        """Frames tracking refused, with the reason."""
        return dict(self._native.rejected_poses())

    @property
    def camera(self) -> Optional[Camera]:
        """The rig record's camera model (``None`` if the capture recorded none)."""
        c = self._native.camera
        return None if c is None else Camera(**c)

    @property
    def rig(self) -> Optional[Dict[str, Any]]:
        """The rig record (``manifest.json``'s ``rig``) as written: camera, flash, radiometry,
        noise, analyser extinction."""
        return self._native.rig

    @property
    def manifest(self) -> Dict[str, Any]:
        """The whole manifest as written."""
        return self._native.manifest

    @property
    def events(self) -> List[Dict[str, Any]]:
        """Every readable event of the log in order; each a dict with its ``type``."""
        return self._native.events

    @property
    def read_report(self) -> str:
        """What reading found wrong (``'intact'`` when nothing)."""
        return self._native.read_report
