"""``ellipso mesh`` and ``ellipso fit`` from Python, with progress and Ctrl-C."""

from __future__ import annotations

import os
from typing import Any, Callable, Dict, Optional, Union

from . import _native
from ._fit import Fit, read_fit
from ._session import Session

PathLike = Union[str, "os.PathLike[str]"]
#: ``progress(kind, text)``: kind is ``'begin'`` (a long step: ``mesh``, ``fit``), ``'stage'``
#: (its current stage), ``'end'`` (its summary line) or ``'line'`` (any other line the
#: command prints: warnings, notes).
Progress = Callable[[str, str], Any]


def _dir(session: Union[Session, PathLike]) -> str:
    return session.path if isinstance(session, Session) else os.fspath(session)


def mesh(
    session: Union[Session, PathLike],
    out: PathLike,
    *,
    vertices: int = 2500,
    progress: Optional[Progress] = None,
) -> Dict[str, Any]:
    """``ellipso mesh SESSION --out OUT --vertices N``: carves the object's mesh from the posed
    frames (tracking frames without a pose first) and writes ``OUT`` (PLY, or OBJ for a
    ``.obj`` name) and its ``-report.json``, each whole.

    Ctrl-C raises ``KeyboardInterrupt`` once the carving reaches its next stage, with neither
    file written (an earlier one is unchanged). Errors raise with the command's message.

    :returns: ``{'mesh_file', 'report_file', 'report', 'wall_s'}``.
    """
    return _native.mesh(_dir(session), os.fspath(out), vertices=vertices, progress=progress)


def fit(
    session: Union[Session, PathLike],
    out: PathLike,
    *,
    mesh: Optional[PathLike] = None,
    vertices: int = 2500,
    outer: Optional[int] = None,
    holdout: float = 0.1,
    joint_only: bool = False,
    normal_prior_deg: float = 10.0,
    grazing_cutoff_deg: Optional[float] = None,
    view: Optional[int] = None,
    no_hull: bool = False,
    progress: Optional[Progress] = None,
) -> Fit:
    """``ellipso fit SESSION --out OUT …``: the per-vertex polarimetric SVBRDF and refined
    shape, written into the folder ``OUT`` whole (docs/fit-outputs.md), then read back.

    The keywords are the command's flags (``mesh=None`` carves the mesh first, with
    ``vertices``). Ctrl-C raises ``KeyboardInterrupt`` once the fit reaches its next stage;
    the output folder is then not written (an earlier one is unchanged). An exception raised
    by ``progress`` stops the fit the same way and is re-raised.

    :returns: the written fit (:func:`read_fit`), with ``run_files`` (every file written).
    """
    kwargs: Dict[str, Any] = dict(
        mesh=None if mesh is None else os.fspath(mesh),
        vertices=vertices,
        outer=outer,
        holdout=float(holdout),
        joint_only=joint_only,
        normal_prior_deg=float(normal_prior_deg),
        view=view,
        no_hull=no_hull,
        progress=progress,
    )
    if grazing_cutoff_deg is not None:
        kwargs["grazing_cutoff_deg"] = float(grazing_cutoff_deg)
    done = _native.fit(_dir(session), os.fspath(out), **kwargs)
    result = read_fit(done["out"])
    result.run_files = [os.fspath(f) for f in done["files"]]
    return result
