"""ellipso from Python: recorded sessions, polarisation, the pBRDF model and fits as numpy
arrays. Every function runs the code of the ``ellipso`` command line (docs/python.md).

- :class:`Session` — a recorded session, read-only: frames, poses, camera, events, rig.
- :func:`polar` — a raw mosaic to s0, s1, s2, DoLP, AoLP, I^d/I^s/I^α and the mask.
- :func:`mueller`, :func:`coaxial`, :func:`fresnel` — the pBRDF model over arrays.
- :func:`read_fit` — a fit folder as arrays; :class:`FitFlag` its flag bits.
- :func:`mesh`, :func:`fit` — ``ellipso mesh`` / ``ellipso fit`` with progress and Ctrl-C.

Errors raise ``TypeError``/``ValueError`` for bad arguments, ``FileNotFoundError`` for missing
files and :class:`EllipsoError` (a ``RuntimeError``) for everything else, with the command
line's messages.
"""

from . import _native
from ._fit import PARAMS, WITHHOLDS_ETA, WITHHOLDS_VERTEX, Fit, FitFlag, PlyError, read_fit
from ._model import coaxial, fresnel, mueller
from ._polar import MASK_BITS, Polar, polar
from ._run import fit, mesh
from ._session import Camera, FrameRecord, Poses, Session

EllipsoError = _native.EllipsoError
__version__ = _native.__version__

__all__ = [
    "Camera", "EllipsoError", "Fit", "FitFlag", "FrameRecord", "MASK_BITS", "PARAMS",
    "PlyError", "Polar", "Poses", "Session", "WITHHOLDS_ETA", "WITHHOLDS_VERTEX", "coaxial",
    "fit", "fresnel", "mesh", "mueller", "polar", "read_fit",
]
