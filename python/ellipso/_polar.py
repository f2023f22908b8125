"""Polarisation of a raw mosaic: ``ellipso.polar`` (the processing of ``ellipso polar``)."""

from __future__ import annotations

from typing import Any, Dict, Iterator, Mapping, Optional

import numpy as np

from . import _native

#: Bits of the mask planes (``mask``): a pixel is valid where its mask is 0.
MASK_BITS = {
    "saturated": 1 << 0,
    "dark": 1 << 1,
    "no_samples": 1 << 2,
    "unphysical": 1 << 3,
    "inconsistent": 1 << 4,
}

_PLANES = ("s0", "s1", "s2", "dolp", "aolp", "residual", "i_d", "i_s", "i_alpha", "mask")


class Polar(Mapping[str, np.ndarray]):
    """Stokes images of one mosaic, as ``ellipso polar`` computes them.

    Every plane is ``float32`` (``mask``: ``uint8`` reason bits, :data:`MASK_BITS`) of shape
    ``(height, width)`` for a mono sensor and ``(3, height, width)`` (R, G, B) for a colour
    one. Values are normalised: ``I = (DN - dark) / (saturation - dark)``, so ``s0`` is in
    ``[0, 2]`` for unclipped data.

    - ``s0 = (I0 + I45 + I90 + I135) / 2``, ``s1 = I0 - I90``, ``s2 = I45 - I135``
    - ``dolp = sqrt(s1² + s2²) / s0``; ``aolp = atan2(s2, s1) / 2`` in ``[0, π)`` radians,
      counter-clockwise from image-right as the image is displayed
    - ``i_d = 2·I90``, ``i_s = I0 - I90`` (the same array as ``s1``), ``i_alpha = I135 - I45``
      (``-s2``, computed when first asked for), ``residual = I0 + I90 - I45 - I135``

    It is a mapping (``result["dolp"]``) and has the planes as attributes (``result.dolp``).
    A mono plane is the array the crate filled (no copy); colour planes are stacked into one
    array when first asked for.
    """

    def __init__(self, raw: Dict[str, Any]) -> None:
        self._bands = raw["bands"]
        self._planes: Dict[str, np.ndarray] = {}
        #: ``'mono'`` or ``'colour'``.
        self.layout: str = raw["layout"]
        #: ``'superpixel'`` or ``'bilinear'``.
        self.demosaic: str = raw["demosaic"]
        #: Bits per sample the frame was read with.
        self.bit_depth: int = raw["bit_depth"]
        #: Black level subtracted, DN.
        self.dark_level_dn: float = raw["dark_level_dn"]
        #: Samples at or above this DN were saturated.
        self.saturation_dn: int = raw["saturation_dn"]

    def _plane(self, name: str) -> np.ndarray:
        p = self._planes.get(name)
        if p is None:
            if name == "i_s":
                p = self._plane("s1")
            elif name == "i_alpha":
                p = np.negative(self._plane("s2"))
            elif len(self._bands) == 1:
                p = self._bands[0][name]
            else:
                p = np.stack([b[name] for b in self._bands])
            self._planes[name] = p
        return p

    def __getitem__(self, key: str) -> np.ndarray:
        if key not in _PLANES:
            raise KeyError(key)
        return self._plane(key)

    def __iter__(self) -> Iterator[str]:
        return iter(_PLANES)

    def __len__(self) -> int:
        return len(_PLANES)

    def __repr__(self) -> str:
        return (f"ellipso.Polar({self.layout}, {self.demosaic}, {self.bit_depth}-bit: "
                f"planes {tuple(self._plane('s0').shape)})")

    s0 = property(lambda self: self._plane("s0"), doc="Total intensity s0.")
    s1 = property(lambda self: self._plane("s1"), doc="s1 = I0 − I90.")
    s2 = property(lambda self: self._plane("s2"), doc="s2 = I45 − I135.")
    dolp = property(lambda self: self._plane("dolp"), doc="Degree of linear polarisation.")
    aolp = property(lambda self: self._plane("aolp"), doc="Angle of linear polarisation, rad, [0, π).")
    residual = property(lambda self: self._plane("residual"), doc="I0 + I90 − I45 − I135.")
    i_d = property(lambda self: self._plane("i_d"), doc="I^d = 2·I90.")
    i_s = property(lambda self: self._plane("i_s"), doc="I^s = I0 − I90 (the s1 array).")
    i_alpha = property(lambda self: self._plane("i_alpha"), doc="I^α = I135 − I45 = −s2.")
    mask = property(lambda self: self._plane("mask"), doc="Reason bits (MASK_BITS); 0 = valid.")

    @property
    def valid(self) -> np.ndarray:
        """``True`` where the pixel's mask is empty."""
        return self.mask == 0


def polar(
    mosaic: np.ndarray,
    layout: Optional[str] = None,
    *,
    bit_depth: Optional[int] = None,
    demosaic: str = "superpixel",
    dark_level: float = 0.0,
    saturation: Optional[int] = None,
    dark_intensity: float = 0.001,
    max_residual: Optional[float] = None,
) -> Polar:
    """Stokes, DoLP, AoLP, the observation channels and the mask of a raw mosaic.

    The same code, defaults and checks as ``ellipso polar FRAME`` (results are bit-identical).

    :param mosaic: the raw frame as the camera delivered it: a 2-D C-contiguous ``uint8`` or
        ``uint16`` array (right-aligned DN). A ``uint16`` array is read in place, never copied
        (a ``uint8`` one is widened to ``u16`` once).
    :param layout: ``'mono'`` (IMX250MZR) or ``'colour'`` (IMX250MYR); ``None`` detects it from
        the pixels and refuses when unclear.
    :param bit_depth: bits per sample; default 8 for ``uint8`` and 12 for ``uint16``.
    :param demosaic: ``'superpixel'`` (half resolution, no interpolation; for measuring) or
        ``'bilinear'`` (full resolution).
    :param dark_level: black level subtracted from every sample, DN.
    :param saturation: samples at or above this DN are saturated (default: full scale).
    :param dark_intensity: pixels whose s0/2 is below this are masked dark.
    :param max_residual: mask pixels whose ``|I0 + I90 - I45 - I135|`` exceeds this.
    :raises TypeError: not an array, or a dtype other than ``uint8``/``uint16``.
    :raises ValueError: not 2-D, not C-contiguous, a size that is not whole mosaic tiles,
        values above the bit depth, bad levels or names.
    """
    raw = _native.polar(
        mosaic,
        layout=layout,
        bit_depth=bit_depth,
        demosaic=demosaic,
        dark_level=float(dark_level),
        saturation=saturation,
        dark_intensity=float(dark_intensity),
        max_residual=None if max_residual is None else float(max_residual),
    )
    return Polar(raw)
