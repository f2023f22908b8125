"""`ellipso.polar` against `ellipso polar` (bit for bit) and polanalyser (1e-6), and its
refusals of bad input."""

import subprocess

import numpy as np
import pytest

import ellipso
from conftest import run_cli


def mosaic(layout="mono", h=48, w=64, bits=12, seed=7):
    """A smooth, partly polarised scene in a raw mosaic, with noise and a few clipped pixels
    (seeded)."""
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:h, 0:w]
    s0 = 0.4 + 0.5 * x / w
    dolp = 0.6 * y / h
    phi = np.pi * (x + 2 * y) / (w + 2 * h)
    # analyser angle θ of each raw pixel: mono 2×2 block "90 45 / 135 0"
    theta = np.array([[90, 45], [135, 0]])[y % 2, x % 2] * np.pi / 180
    i = 0.5 * s0 * (1 + dolp * np.cos(2 * (theta - phi)))
    if layout == "colour":
        i = i * np.array([[0.6, 1.0], [1.0, 0.7]])[(y // 2) % 2, (x // 2) % 2]
    full = 2**bits - 1
    dn = np.clip(np.round(i * full + rng.normal(0, 3, i.shape)), 0, full)
    dn[3, 5] = full  # a saturated sample
    return dn.astype(np.uint16 if bits > 8 else np.uint8)


def test_agrees_with_polanalyser_where_conventions_match():
    """Mapping: polanalyser's superpixel convention for the IMX250MZR is the 2×2 block
    (0,0)=90°, (0,1)=45°, (1,0)=135°, (1,1)=0° (its demosaicing module says so), which is ours;
    ellipso normalises I = DN / (2^bits − 1) (dark level 0), so polanalyser is given the same
    normalised intensities; its `calcLinearStokes` at analyser angles 0, 45, 90, 135° gives
    s0 = ½ΣI, s1 = I0 − I90, s2 = I45 − I135 as ours; DoLP and AoLP (in [0, π)) likewise.
    polanalyser's own demosaicing is bilinear through OpenCV's Bayer kernels, which our
    `bilinear` does not copy, so only superpixel output is compared."""
    pa = pytest.importorskip("polanalyser")
    raw = mosaic()
    r = ellipso.polar(raw, layout="mono", bit_depth=12)
    norm = raw.astype(np.float64) / 4095.0
    i0, i45, i90, i135 = norm[1::2, 1::2], norm[0::2, 1::2], norm[0::2, 0::2], norm[1::2, 0::2]
    stokes = pa.calcLinearStokes(np.stack([i0, i45, i90, i135]), np.deg2rad([0, 45, 90, 135]))
    for k, name in enumerate(("s0", "s1", "s2")):
        np.testing.assert_allclose(r[name], stokes[..., k], rtol=0, atol=1e-6, err_msg=name)
    valid = r.valid
    assert valid.mean() > 0.9
    np.testing.assert_allclose(r.dolp[valid], pa.cvtStokesToDoLP(stokes)[valid], rtol=0, atol=1e-6)
    d = r.aolp[valid] - pa.cvtStokesToAoLP(stokes)[valid]
    d = (d + np.pi / 2) % np.pi - np.pi / 2  # 0 and π are one angle
    assert np.abs(d).max() < 1e-6
    # the observation channels: I^d = 2·I90, I^s = s1, I^α = −s2
    np.testing.assert_allclose(r.i_d, 2 * i90, rtol=0, atol=1e-6)
    assert r.i_s is r.s1
    assert np.array_equal(r.i_alpha, -r.s2)


@pytest.mark.parametrize(
    "layout,demosaic,dtype",
    [("mono", "superpixel", "u2"), ("mono", "bilinear", "u2"), ("colour", "superpixel", "u2"),
     ("colour", "bilinear", "u1")],
)
def test_bit_identical_with_ellipso_polar(ellipso_bin, tmp_path, layout, demosaic, dtype):
    bits = 8 if dtype == "u1" else 12
    raw = mosaic(layout, bits=bits)
    np.save(tmp_path / "frame.npy", raw)
    out = tmp_path / "out"
    run_cli(ellipso_bin, "polar", tmp_path / "frame.npy", "--out", out, "--npy",
            "--layout", layout, "--demosaic", demosaic)
    r = ellipso.polar(raw, layout=layout, demosaic=demosaic)
    names = {"s0": "s0", "s1": "s1", "s2": "s2", "dolp": "dolp", "aolp_rad": "aolp",
             "residual": "residual", "i_d": "i_d", "mask": "mask"}
    bands = [""] if layout == "mono" else ["_r", "_g", "_b"]
    for b, suffix in enumerate(bands):
        for file, plane in names.items():
            cli = np.load(out / f"{file}{suffix}.npy")
            ours = r[plane] if layout == "mono" else r[plane][b]
            assert cli.shape == ours.shape, (file, suffix)
            # bit for bit (NaN-safe): compare the raw bytes
            assert cli.tobytes() == np.ascontiguousarray(ours).astype(cli.dtype).tobytes(), (file, suffix)


def test_layout_detected_and_defaults_as_the_cli():
    r = ellipso.polar(mosaic("colour"))
    assert r.layout == "colour" and r.s0.shape == (3, 12, 16)
    assert ellipso.polar(mosaic("mono")).layout == "mono"
    assert ellipso.polar(mosaic(bits=8)).bit_depth == 8
    assert ellipso.polar(mosaic()).bit_depth == 12
    with pytest.raises(ValueError, match="cannot tell a mono"):
        ellipso.polar(np.zeros((48, 64), np.uint16))


def test_bad_input_raises_clear_exceptions():
    raw = mosaic()
    with pytest.raises(TypeError, match="dtype float64"):
        ellipso.polar(raw.astype(np.float64), layout="mono")
    with pytest.raises(TypeError, match="dtype int32"):
        ellipso.polar(raw.astype(np.int32), layout="mono")
    with pytest.raises(TypeError, match="native byte order"):
        ellipso.polar(raw.astype(">u2"), layout="mono")
    with pytest.raises(TypeError, match="numpy array"):
        ellipso.polar(raw.tolist(), layout="mono")
    with pytest.raises(ValueError, match="2-D"):
        ellipso.polar(np.stack([raw, raw]), layout="mono")
    with pytest.raises(ValueError, match="not C-contiguous"):
        ellipso.polar(raw[:, ::2], layout="mono")
    with pytest.raises(ValueError, match="not C-contiguous"):
        ellipso.polar(raw.T, layout="mono")
    with pytest.raises(ValueError, match="3×2"):
        ellipso.polar(np.zeros((2, 3), np.uint16), layout="mono")
    with pytest.raises(ValueError, match="exceeds the 12-bit maximum"):
        ellipso.polar(np.full((4, 4), 4096, np.uint16), layout="mono")
    with pytest.raises(ValueError, match="layout 'grey'"):
        ellipso.polar(raw, layout="grey")
    with pytest.raises(ValueError, match="demosaic"):
        ellipso.polar(raw, layout="mono", demosaic="vng")
    with pytest.raises(ValueError, match="dark level"):
        ellipso.polar(raw, layout="mono", dark_level=5000)
    with pytest.raises(ValueError, match="bit_depth 17"):
        ellipso.polar(raw, layout="mono", bit_depth=17)
    with pytest.raises(ValueError):
        ellipso.polar(np.zeros((0, 0), np.uint16), layout="mono")


def test_outputs_are_arrays_the_caller_owns():
    r = ellipso.polar(mosaic(), layout="mono")
    assert r.s0.dtype == np.float32 and r.mask.dtype == np.uint8
    assert r.s0.flags.c_contiguous and r.s0.flags.writeable
    # handed over, not copied: numpy holds the crate's vector through a base object
    assert not r.s0.flags.owndata and r.s0.base is not None
    assert set(r) == {"s0", "s1", "s2", "dolp", "aolp", "residual", "i_d", "i_s", "i_alpha", "mask"}
