"""`ellipso.read_fit` against plyfile (every property, its type, its values; the flags), and
`ellipso.fit`/`ellipso.mesh` run from Python: progress, Ctrl-C, errors."""

import os
import signal
import threading

import numpy as np
import pytest

import ellipso
from ellipso import FitFlag


def test_read_fit_gives_every_property_of_fit_ply(fit_dir):
    plyfile = pytest.importorskip("plyfile")
    ply = plyfile.PlyData.read(str(fit_dir / "fit.ply"))
    vertex = ply["vertex"]
    fit = ellipso.read_fit(fit_dir)
    names = [p.name for p in vertex.properties]
    assert list(fit) == names
    assert {"seen_lit", "gated_mixed", "flags", "std_eta", "red"} <= set(names)
    for name in names:
        theirs = vertex[name]
        assert fit[name].dtype == theirs.dtype.newbyteorder("="), name
        assert fit[name].tobytes() == theirs.astype(fit[name].dtype).tobytes(), name
    faces = np.stack(ply["face"]["vertex_indices"])
    assert np.array_equal(fit.faces, faces)
    assert fit.positions.shape == (len(vertex.data), 3) and fit.positions.dtype == np.float64
    assert set(fit.params) == set(ellipso.PARAMS) and set(fit.std) == set(ellipso.PARAMS)
    assert fit.summary["vertices"] == fit.vertex_count
    assert fit.partition is not None


def test_flags_are_the_fits_bits(fit_dir):
    assert [f.name for f in FitFlag] == ellipso._native.fit_flag_names()
    fit = ellipso.read_fit(fit_dir)
    for v in range(fit.vertex_count):
        assert int(fit.flags_of(v)) == int(fit.flags[v])
    # the identifiability rule as the file applies it: what it withholds has σ = +inf
    vertex, eta = fit.identifiable()
    assert np.isinf(fit["std_eta"][~eta]).all()
    for p in ellipso.PARAMS:
        assert np.isinf(fit["std_" + p][~vertex]).all(), p
    assert (~vertex).any() and vertex.any()
    assert fit.has(FitFlag.Unobserved).any()  # the underside of the sphere
    assert not vertex[fit.has(FitFlag.Unobserved)].any()


def test_material_per_vertex_is_read_from_fit_ply(fit_dir):
    # the material partition from disk: fit.ply's `material` column, the assignment whose
    # per-material counts fit-summary.json reports (observed vertices of each material)
    fit = ellipso.read_fit(fit_dir)
    material = fit.material
    assert material is fit["material"] and material.dtype == np.int32
    assert material.shape == (fit.vertex_count,)
    k = len(fit.materials)
    assert k >= 1 and fit.summary["materials"]
    assert ((material >= -1) & (material < k)).all()
    observed = ~fit.has(FitFlag.Unobserved)
    for m in fit.summary["materials"]:
        assert ((material == m["cluster"]) & observed).sum() == m["observed"], m
    assert (material >= 0).any()


def test_read_fit_refuses_what_is_not_a_fit(tmp_path):
    with pytest.raises(FileNotFoundError, match="fit.ply"):
        ellipso.read_fit(tmp_path)
    (tmp_path / "fit.ply").write_bytes(b"not a ply")
    with pytest.raises(ValueError, match="not a PLY"):
        ellipso.read_fit(tmp_path)


def test_fit_from_python_with_progress(session_dir, fit_dir, tmp_path):
    seen = []
    out = tmp_path / "fit"
    fit = ellipso.fit(ellipso.Session(session_dir), out, mesh=fit_dir / "mesh.ply", outer=1,
                      no_hull=True, progress=lambda kind, text: seen.append((kind, text)))
    assert ("begin", "fit") in seen and any(k == "stage" for k, _ in seen)
    assert any(k == "end" for k, _ in seen)
    assert (out / "fit.ply").exists() and fit.material.shape == (fit.vertex_count,)
    assert fit.run_files
    # the same settings from the command line give the same file
    assert fit.vertex_count == ellipso.read_fit(fit_dir).vertex_count


def _leftovers(parent, keep):
    return sorted(p.name for p in parent.iterdir() if p.name not in keep)


def test_a_callback_exception_stops_the_fit_with_nothing_written(session_dir, fit_dir, tmp_path):
    class Stop(Exception):
        pass

    def progress(kind, text):
        if kind == "stage":
            raise Stop(text)

    out = tmp_path / "fit"
    with pytest.raises(Stop):
        ellipso.fit(session_dir, out, mesh=fit_dir / "mesh.ply", outer=1, no_hull=True, progress=progress)
    assert not out.exists() and _leftovers(tmp_path, set()) == []


def test_ctrl_c_stops_the_fit_with_nothing_written(session_dir, fit_dir, tmp_path):
    out = tmp_path / "fit"
    started = threading.Event()

    def progress(kind, text):
        # Ctrl-C during the first stage, delivered at once (a timer raced the fit, which can
        # finish within its delay on a fast machine).
        if kind == "stage" and not started.is_set():
            started.set()
            os.kill(os.getpid(), signal.SIGINT)

    # Python leaves SIGINT ignored when it started with it ignored (a job started in the
    # background by a non-interactive shell): Ctrl-C's handler is set here, as a terminal has it.
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        with pytest.raises(KeyboardInterrupt):
            ellipso.fit(session_dir, out, mesh=fit_dir / "mesh.ply", outer=2, no_hull=True, progress=progress)
    finally:
        signal.signal(signal.SIGINT, previous)
    assert started.is_set()
    assert not out.exists() and _leftovers(tmp_path, set()) == []


def test_fit_and_mesh_errors_are_the_clis(tmp_path, session_dir):
    with pytest.raises(FileNotFoundError, match="manifest.json"):
        ellipso.fit(tmp_path / "nowhere", tmp_path / "out")
    with pytest.raises(ValueError, match="outer 30 is outside 1..=20"):
        ellipso.fit(session_dir, tmp_path / "out", outer=30)
    with pytest.raises(ValueError, match="vertices 5 is outside"):
        ellipso.mesh(session_dir, tmp_path / "m.ply", vertices=5)
    assert not (tmp_path / "out").exists()


def test_mesh_from_python(session_dir, tmp_path):
    lines = []
    done = ellipso.mesh(session_dir, tmp_path / "m.ply", vertices=300, progress=lambda k, t: lines.append(k))
    assert (tmp_path / "m.ply").exists() and done["report"]["vertices"] > 100
    assert "begin" in lines and "end" in lines
