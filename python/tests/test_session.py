"""`ellipso.Session`: frames as recorded, poses with their frame, camera, events, rig; and
the refusals (a missing session, a corrupt frame)."""

import json
import shutil

import numpy as np
import pytest

import ellipso
from conftest import run_cli


def test_frames_are_the_recorded_pngs(session_dir):
    s = ellipso.Session(session_dir)
    assert (s.width, s.height, s.layout) == (612, 512, "mono")
    assert len(s) == 24 and list(s.frame_ids) == list(range(24))
    f = s.frame(3)
    assert f.dtype == np.uint16 and f.shape == (512, 612)
    assert f.max() <= 2**s.bit_depth - 1 and f.max() > 0
    Image = pytest.importorskip("PIL.Image")
    with Image.open(session_dir / "frames" / "00000003.png") as im:
        assert np.array_equal(np.asarray(im).astype(np.uint16), f)
    r = s.frames[3]
    assert r.frame_id == 3 and r.complete and r.file.endswith("00000003.png")


def test_poses_camera_events_rig(session_dir):
    s = ellipso.Session(session_dir)
    p = s.poses
    assert p.frame == "world_from_camera"
    n = len(p)
    assert n >= 20 and p.world_from_camera.shape == (n, 4, 4)
    R = p.world_from_camera[:, :3, :3]
    np.testing.assert_allclose(R @ R.transpose(0, 2, 1), np.broadcast_to(np.eye(3), R.shape), atol=1e-9)
    np.testing.assert_array_equal(p.world_from_camera[:, 3], np.broadcast_to([0, 0, 0, 1], (n, 4)))
    # every camera is above the board (z up), looking down at it (its +z axis points down)
    assert (p.world_from_camera[:, 2, 3] > 0).all()
    assert (p.world_from_camera[:, 2, 2] < 0).all()
    with pytest.raises(ValueError):
        p.world_from_camera[0, 0, 0] = 1.0  # read-only
    c = s.camera
    assert (c.width, c.height) == (612, 512)
    assert c.K.shape == (3, 3) and c.K[0, 0] == c.fx and c.distortion.shape == (5,)
    manifest = json.loads((session_dir / "manifest.json").read_text())
    assert s.manifest["sensor"] == manifest["sensor"]
    assert s.rig["camera"]["fx"] == c.fx
    kinds = {e["type"] for e in s.events}
    assert {"frame", "pose"} <= kinds
    assert s.read_report == "intact"


def test_a_frame_polarised_from_python_is_ellipso_polar_of_it(ellipso_bin, session_dir, tmp_path):
    s = ellipso.Session(session_dir)
    r = ellipso.polar(s.frame(5), layout=s.layout, bit_depth=s.bit_depth)
    run_cli(ellipso_bin, "polar", session_dir / "frames" / "00000005.png", "--out", tmp_path / "p", "--npy")
    for file, plane in (("s0", "s0"), ("dolp", "dolp"), ("aolp_rad", "aolp"), ("mask", "mask")):
        assert np.load(tmp_path / "p" / f"{file}.npy").tobytes() == r[plane].tobytes()


def test_missing_session_and_frame(tmp_path, session_dir):
    with pytest.raises(FileNotFoundError, match="manifest.json"):
        ellipso.Session(tmp_path / "nowhere")
    s = ellipso.Session(session_dir)
    with pytest.raises(KeyError, match="no frame 99"):
        s.frame(99)


def test_corrupt_frame_and_manifest_raise(session_dir, tmp_path):
    copy = tmp_path / "s"
    shutil.copytree(session_dir, copy)
    png = copy / "frames" / "00000002.png"
    png.write_bytes(png.read_bytes()[:200])
    s = ellipso.Session(copy)
    with pytest.raises(ValueError, match="00000002.png"):
        s.frame(2)
    assert s.frame(1).shape == (512, 612)  # the others still read
    (copy / "manifest.json").write_text("{ not json")
    with pytest.raises(ValueError, match="manifest"):
        ellipso.Session(copy)
