"""The model over arrays against `ellipso model` (one element at a time) and physics."""

import json

import numpy as np
import pytest

import ellipso
from conftest import run_cli

MATERIAL = dict(eta=1.5, sigma_s=0.2, sigma_ss=0.4, rho_s=0.8, rho_ss=[0.1, 0.2, 0.3], rho_d=[0.5, 0.4, 0.3])


def test_mueller_matches_the_cli_and_broadcasts(ellipso_bin):
    rng = np.random.default_rng(3)
    normal = np.array([0.0, 0.0, 1.0]) + 0.3 * rng.normal(size=(2, 3, 3))
    to_light = np.array([0.3, 0.1, 1.0])
    to_camera = np.array([-0.2, 0.0, 1.0])
    out = ellipso.mueller(normal, to_light, to_camera, **MATERIAL)
    assert out["total"].shape == (2, 3, 3, 4, 4) and out["specular"].shape == (2, 3, 4, 4)
    n = normal[1, 2]
    p = run_cli(
        ellipso_bin, "model", "mueller", "--json", "--eta", "1.5", "--sigma-s", "0.2", "--sigma-ss", "0.4",
        "--rho-s", "0.8", "--rho-ss", "0.1,0.2,0.3", "--rho-d", "0.5,0.4,0.3",
        "--normal", ",".join(repr(float(v)) for v in n), "--to-light", "0.3,0.1,1", "--to-camera", "-0.2,0,1",
    )
    cli = json.loads(p.stdout)
    np.testing.assert_array_equal(out["total"][1, 2], np.array(cli["total"]))
    np.testing.assert_array_equal(out["specular"][1, 2], np.array(cli["specular"]))


def test_fresnel_and_coaxial():
    f = ellipso.fresnel([1.5, 1.33], 0.0)
    np.testing.assert_allclose(f["r_plus"], ((np.array([1.5, 1.33]) - 1) / (np.array([1.5, 1.33]) + 1)) ** 2)
    np.testing.assert_allclose(f["r_plus"] + f["t_plus"], 1.0)
    m = ellipso.coaxial([[0.0, 0.0, 1.0], [0.5, 0.2, 1.0]], **MATERIAL)
    assert m.shape == (2, 3, 3, 3)
    # facing the camera: no diffuse polarisation, so the block is diagonal-ish
    assert m[0, 0, 0, 1] == 0 and m[0, 0, 0, 2] == 0
    assert m[1, 0, 0, 2] != 0


def test_bad_model_inputs_name_the_element():
    with pytest.raises(ValueError, match=r"element 1: --eta must be in \[1, 5\]"):
        ellipso.mueller([0, 0, 1], [0, 0, 1], [0, 0, 1], **{**MATERIAL, "eta": [1.5, 7.0]})
    with pytest.raises(ValueError, match="--normal must be a non-zero vector"):
        ellipso.mueller([0, 0, 0], [0, 0, 1], [0, 0, 1], **MATERIAL)
    with pytest.raises(ValueError, match="last axis of 3"):
        ellipso.mueller([0, 1], [0, 0, 1], [0, 0, 1], **MATERIAL)
    with pytest.raises(ValueError, match="theta"):
        ellipso.fresnel(1.5, 120.0)
