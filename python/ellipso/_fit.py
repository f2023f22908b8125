"""A fit folder as arrays: ``ellipso.read_fit(dir)``; the fit's flags as ``enum.IntFlag``.

``fit.ply``'s header is parsed generically: every per-vertex property, whatever its name or
type, becomes an array of that PLY type (``double`` → ``float64``, ``float`` → ``float32``,
``int`` → ``int32``, ``uchar`` → ``uint8``, …), so columns added to the file later are read
too. docs/fit-outputs.md describes the properties.
"""

from __future__ import annotations

import enum
import json
import os
from typing import Any, Dict, Iterator, List, Mapping, Optional, Tuple, Union

import numpy as np

PathLike = Union[str, "os.PathLike[str]"]


class FitFlag(enum.IntFlag):
    """Bits of ``fit.ply``'s ``flags`` (and ``maps.exr``'s): ``ellipso_fit::data::FitFlag``."""

    TooFewViews = 1 << 0
    UnderDetermined = 1 << 1
    Dark = 1 << 2
    Saturated = 1 << 3
    EtaUnidentifiable = 1 << 4
    GrazingOnly = 1 << 5
    AtBound = 1 << 6
    NotConverged = 1 << 7
    AlbedoAtCap = 1 << 8
    NormalUnconstrained = 1 << 9
    EtaPooled = 1 << 10
    Unobserved = 1 << 11
    FromMaterial = 1 << 12
    MaterialEtaUnidentified = 1 << 13


#: Flags that withhold every parameter of a vertex (the identifiability rule,
#: docs/fit-outputs.md), unless ``FromMaterial`` lifts them (``Unobserved`` it never lifts).
WITHHOLDS_VERTEX = FitFlag.TooFewViews | FitFlag.AlbedoAtCap | FitFlag.Unobserved
#: Flags that withhold η.
WITHHOLDS_ETA = WITHHOLDS_VERTEX | FitFlag.EtaUnidentifiable | FitFlag.MaterialEtaUnidentified

#: The fitted parameters, in the order of their standard errors ``std_<name>``.
PARAMS = (
    "eta", "sigma_s", "sigma_ss", "rho_s", "rho_ss_r", "rho_ss_g", "rho_ss_b",
    "rho_d_r", "rho_d_g", "rho_d_b",
)

_PLY_TYPES = {
    "char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1",
    "short": "i2", "int16": "i2", "ushort": "u2", "uint16": "u2",
    "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
    "float": "f4", "float32": "f4", "double": "f8", "float64": "f8",
}


class PlyError(ValueError):
    """A file that is not a PLY this reader understands (the message names file and line)."""


def _header(path: str, data: bytes) -> Tuple[str, List[Tuple[str, int, list]], int]:
    """``(format, [(element, count, properties)], body offset)``; a property is
    ``(name, type)`` or ``(name, ('list', count type, item type))``."""
    end = data.find(b"end_header")
    if not data.startswith(b"ply") or end < 0:
        raise PlyError(f"{path}: not a PLY file (no 'ply' magic or no 'end_header')")
    newline = data.find(b"\n", end)
    body = newline + 1 if newline >= 0 else len(data)
    fmt = None
    elements: List[Tuple[str, int, list]] = []
    for number, raw in enumerate(data[:end].decode("ascii", "replace").splitlines(), 1):
        words = raw.split()
        if not words or words[0] in ("ply", "comment", "obj_info"):
            continue

        def bad(what: str) -> PlyError:
            return PlyError(f"{path}: header line {number}: {what}: {raw!r}")

        if words[0] == "format":
            if len(words) < 2:
                raise bad("format without a name")
            fmt = words[1]
        elif words[0] == "element":
            if len(words) != 3 or not words[2].isdigit():
                raise bad("expected 'element NAME COUNT'")
            elements.append((words[1], int(words[2]), []))
        elif words[0] == "property":
            if not elements:
                raise bad("a property before any element")
            if words[1] == "list":
                if len(words) != 5 or words[2] not in _PLY_TYPES or words[3] not in _PLY_TYPES:
                    raise bad("expected 'property list COUNT_TYPE ITEM_TYPE NAME'")
                elements[-1][2].append((words[4], ("list", words[2], words[3])))
            else:
                if len(words) != 3 or words[1] not in _PLY_TYPES:
                    raise bad("unknown property type")
                elements[-1][2].append((words[2], words[1]))
        else:
            raise bad("unknown header keyword")
    if fmt not in ("binary_little_endian", "binary_big_endian", "ascii"):
        raise PlyError(f"{path}: unsupported PLY format {fmt!r}")
    return fmt, elements, body


def _read_ply(path: str) -> Tuple[Dict[str, np.ndarray], Optional[np.ndarray]]:
    """Every vertex property by name, and the faces as an ``(m, k)`` array (triangles:
    ``k = 3``) when every face has the same count."""
    with open(path, "rb") as f:
        data = f.read()
    fmt, elements, offset = _header(path, data)
    if fmt == "ascii":
        return _read_ascii(path, data[offset:].decode("ascii", "replace"), elements)
    order = "<" if fmt == "binary_little_endian" else ">"
    vertex: Dict[str, np.ndarray] = {}
    faces: Optional[np.ndarray] = None
    for name, count, props in elements:
        if all(not isinstance(t, tuple) for _, t in props):
            dtype = np.dtype([(p, order + _PLY_TYPES[t]) for p, t in props])
            size = dtype.itemsize * count
            if offset + size > len(data):
                raise PlyError(f"{path}: element {name!r} is cut short ({count} × {dtype.itemsize} bytes expected)")
            table = np.frombuffer(data, dtype=dtype, count=count, offset=offset)
            offset += size
            if name == "vertex":
                vertex = {p: table[p].astype(_PLY_TYPES[t]) for p, t in props}
        elif len(props) == 1 and name == "face":
            _, (_, count_type, item_type) = props[0]
            ct = np.dtype(order + _PLY_TYPES[count_type])
            it = np.dtype(order + _PLY_TYPES[item_type])
            if count == 0:
                faces = np.zeros((0, 3), dtype=_PLY_TYPES[item_type])
                continue
            k = int(np.frombuffer(data, dtype=ct, count=1, offset=offset)[0])
            rec = np.dtype([("n", ct), ("i", it, (k,))])
            if offset + rec.itemsize * count > len(data):
                raise PlyError(f"{path}: faces are cut short")
            table = np.frombuffer(data, dtype=rec, count=count, offset=offset)
            if np.any(table["n"] != k):
                raise PlyError(f"{path}: faces of mixed sizes are not supported")
            faces = table["i"].astype(_PLY_TYPES[item_type])
            offset += rec.itemsize * count
        else:
            raise PlyError(f"{path}: element {name!r} with list properties is not supported")
    return vertex, faces


def _read_ascii(path: str, text: str, elements) -> Tuple[Dict[str, np.ndarray], Optional[np.ndarray]]:
    lines = iter(text.splitlines())
    vertex: Dict[str, np.ndarray] = {}
    faces = None
    for name, count, props in elements:
        rows = [next(lines).split() for _ in range(count)]
        if name == "vertex":
            for j, (p, t) in enumerate(props):
                vertex[p] = np.array([r[j] for r in rows], dtype=np.float64).astype(_PLY_TYPES[t])
        elif name == "face":
            _, (_, _, item_type) = props[0]
            faces = np.array([[int(x) for x in r[1:]] for r in rows], dtype=_PLY_TYPES[item_type])
    return vertex, faces


class Fit(Mapping[str, np.ndarray]):
    """A fit folder: a mapping from every per-vertex property name of ``fit.ply`` to its array
    (same values, same type), with the mesh, parameters and materials as attributes."""

    def __init__(
        self,
        path: str,
        vertex: Dict[str, np.ndarray],
        faces: Optional[np.ndarray],
        summary: Optional[Dict[str, Any]],
    ) -> None:
        self.path = path
        self._vertex = vertex
        for a in vertex.values():
            a.setflags(write=False)
        #: Triangles, ``(m, 3)`` vertex indices (``int32``).
        self.faces = faces
        #: ``fit-summary.json`` (``None`` when the folder has none).
        self.summary = summary

    def __getitem__(self, name: str) -> np.ndarray:
        return self._vertex[name]

    def __iter__(self) -> Iterator[str]:
        return iter(self._vertex)

    def __len__(self) -> int:
        return len(self._vertex)

    def __repr__(self) -> str:
        n = len(next(iter(self._vertex.values()))) if self._vertex else 0
        return f"ellipso.Fit({self.path!r}: {n} vertices, {len(self._vertex)} properties)"

    @property
    def vertex_count(self) -> int:
        return len(self._vertex["x"])

    @property
    def positions(self) -> np.ndarray:
        """Refined positions, ``(n, 3)`` ``float64``, board frame, metres."""
        return np.stack([self["x"], self["y"], self["z"]], axis=1)

    @property
    def normals(self) -> np.ndarray:
        """Refined unit normals, ``(n, 3)`` ``float32``, board frame."""
        return np.stack([self["nx"], self["ny"], self["nz"]], axis=1)

    @property
    def params(self) -> Dict[str, np.ndarray]:
        """Every fitted parameter by name (:data:`PARAMS`)."""
        return {p: self[p] for p in PARAMS if p in self}

    @property
    def std(self) -> Dict[str, np.ndarray]:
        """The standard error of every parameter (``+inf`` where the identifiability rule
        withholds it)."""
        return {p: self["std_" + p] for p in PARAMS if "std_" + p in self}

    @property
    def flags(self) -> np.ndarray:
        """The ``flags`` column (``int32`` bitmask of :class:`FitFlag`)."""
        return self["flags"]

    def flags_of(self, vertex: int) -> FitFlag:
        """The flags of one vertex as a :class:`FitFlag`."""
        return FitFlag(int(self["flags"][vertex]))

    def has(self, flag: FitFlag) -> np.ndarray:
        """``True`` for every vertex with ``flag`` (any of the bits, for a combination)."""
        return (self["flags"] & int(flag)) != 0

    def identifiable(self) -> Tuple[np.ndarray, np.ndarray]:
        """The identifiability rule over the flags (``ellipso_fit::data::Identifiable``):
        ``(vertex, eta)`` booleans, ``True`` where the vertex's parameters (its η) are
        measurements. ``FromMaterial`` lifts every withholding but ``Unobserved``'s (and η's
        where ``MaterialEtaUnidentified`` says the material has none)."""
        flags = self["flags"].astype(np.int64)
        from_material = (flags & int(FitFlag.FromMaterial)) != 0
        seen = (flags & int(FitFlag.Unobserved)) == 0
        vertex = np.where(from_material, seen, (flags & int(WITHHOLDS_VERTEX)) == 0)
        material_eta = (flags & int(FitFlag.MaterialEtaUnidentified)) == 0
        eta = np.where(from_material, seen & material_eta, (flags & int(WITHHOLDS_ETA)) == 0)
        return vertex, eta

    @property
    def eta_reported(self) -> np.ndarray:
        """``True`` where η is a measurement (its standard error is finite)."""
        return np.isfinite(self["std_eta"])

    @property
    def partition(self) -> Optional[Dict[str, Any]]:
        """How the fit grouped the vertices into materials (``fit-summary.json``'s
        ``partition``: ``k``, ``sizes``, ``members``, ``silhouette`` …)."""
        return None if self.summary is None else self.summary.get("partition")

    @property
    def materials(self) -> List[Dict[str, Any]]:
        """The materials (step B's clusters) with their two-lobe models and pooled η."""
        if self.summary is None:
            return []
        return list(self.summary.get("clusters") or [])

    @property
    def material(self) -> Optional[np.ndarray]:
        """Material of every vertex (``int32``): the index of step B's cluster in
        :attr:`materials` order, ``-1`` where the vertex has none — ``fit.ply``'s ``material``
        column (docs/fit-outputs.md); ``None`` for a ``fit.ply`` written before it existed."""
        return self._vertex.get("material")


def read_fit(path: PathLike) -> Fit:
    """Reads a fit folder (``ellipso fit --out DIR``, the demo's ``fit/``) or its ``fit.ply``.

    :returns: a :class:`Fit`: ``fit["eta"]`` … for every per-vertex property of ``fit.ply``
        (same values and PLY types), ``positions``, ``faces``, ``params``, ``std``,
        ``flags`` (:class:`FitFlag` bits), ``material`` (per vertex), ``summary``,
        ``partition`` and ``materials``.
    :raises FileNotFoundError: no ``fit.ply`` at ``path``.
    :raises ValueError: a file that is not a readable PLY.
    """
    path = os.fspath(path)
    ply = os.path.join(path, "fit.ply") if os.path.isdir(path) else path
    folder = os.path.dirname(ply)
    if not os.path.exists(ply):
        raise FileNotFoundError(f"{ply}: no such file (is {path} an `ellipso fit` output folder?)")
    vertex, faces = _read_ply(ply)
    if "x" not in vertex:
        raise PlyError(f"{ply}: no vertex positions (x, y, z)")
    summary_path = os.path.join(folder, "fit-summary.json")
    summary = None
    if os.path.exists(summary_path):
        with open(summary_path, encoding="utf-8") as f:
            summary = json.load(f)
    return Fit(path, vertex, faces, summary)
