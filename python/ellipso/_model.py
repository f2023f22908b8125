"""The pBRDF model over arrays: Mueller matrices, the coaxial 3×3 block, Fresnel terms.

Every function broadcasts its arguments numpy's way (vectors and RGB albedos have a last axis
of 3; a scalar albedo is grey) and evaluates each element with the code of ``ellipso model``
(docs/model.md). A bad element raises ``ValueError`` naming its flat index and the command's
message.
"""

from __future__ import annotations

from typing import Dict, Tuple

import numpy as np
import numpy.typing as npt

from . import _native

ArrayLike = npt.ArrayLike


def _batch(
    scalars: Dict[str, ArrayLike], vectors: Dict[str, ArrayLike]
) -> Tuple[Tuple[int, ...], Dict[str, np.ndarray], Dict[str, np.ndarray]]:
    sc = {k: np.asarray(v, dtype=np.float64) for k, v in scalars.items()}
    ve = {}
    for k, v in vectors.items():
        a = np.asarray(v, dtype=np.float64)
        if a.ndim == 0 and k.startswith("rho"):
            a = np.repeat(a, 3)
        if a.shape[-1:] != (3,):
            raise ValueError(f"{k} must have a last axis of 3, got shape {a.shape}")
        ve[k] = a
    shape = np.broadcast_shapes(
        *(a.shape for a in sc.values()), *(a.shape[:-1] for a in ve.values())
    )
    n = int(np.prod(shape, dtype=np.int64))
    flat_s = {
        k: np.ascontiguousarray(np.broadcast_to(a, shape).reshape(n)) for k, a in sc.items()
    }
    flat_v = {
        k: np.ascontiguousarray(np.broadcast_to(a, shape + (3,)).reshape(n, 3))
        for k, a in ve.items()
    }
    return shape, flat_s, flat_v


def mueller(
    normal: ArrayLike,
    to_light: ArrayLike,
    to_camera: ArrayLike,
    *,
    eta: ArrayLike,
    sigma_s: ArrayLike,
    sigma_ss: ArrayLike,
    rho_s: ArrayLike,
    rho_ss: ArrayLike,
    rho_d: ArrayLike,
    light_up: ArrayLike = (0.0, 1.0, 0.0),
    camera_up: ArrayLike = (0.0, 1.0, 0.0),
) -> Dict[str, np.ndarray]:
    """The pBRDF's Mueller matrices (``ellipso model mueller``) for arrays of geometries and
    materials.

    Directions are world vectors of any non-zero length (normalised here): the surface
    ``normal``, ``to_light`` (surface → light) and ``to_camera`` (surface → camera); the Stokes
    frames are built from ``light_up`` and ``camera_up``. Parameters: ``eta`` ≥ 1,
    ``0 ≤ sigma_s ≤ sigma_ss ≤ 1``, ``rho_s`` ≥ 0, ``rho_ss`` and ``rho_d`` RGB (last axis 3) or
    grey scalars.

    Returns, for the broadcast shape ``S``: ``total`` ``S + (3, 4, 4)`` (P = P^d + P^s + P^ss
    per RGB channel, light frame → camera frame, foreshortening included), ``diffuse``
    ``S + (3, 4, 4)``, ``specular`` ``S + (4, 4)``, ``single_scattering`` ``S + (3, 4, 4)``,
    ``front_facing`` ``S`` (bool; back-facing geometry gives zero matrices).
    """
    shape, s, v = _batch(
        dict(eta=eta, sigma_s=sigma_s, sigma_ss=sigma_ss, rho_s=rho_s),
        dict(
            rho_ss=rho_ss,
            rho_d=rho_d,
            normal=normal,
            to_light=to_light,
            to_camera=to_camera,
            light_up=light_up,
            camera_up=camera_up,
        ),
    )
    out = _native.mueller(
        s["eta"], s["sigma_s"], s["sigma_ss"], s["rho_s"], v["rho_ss"], v["rho_d"],
        v["normal"], v["to_light"], v["to_camera"], v["light_up"], v["camera_up"],
    )
    return {k: a.reshape(shape + a.shape[1:]) for k, a in out.items()}


def coaxial(
    normal_camera: ArrayLike,
    *,
    eta: ArrayLike,
    sigma_s: ArrayLike,
    sigma_ss: ArrayLike,
    rho_s: ArrayLike,
    rho_ss: ArrayLike,
    rho_d: ArrayLike,
) -> np.ndarray:
    """The coaxial 3×3 linear Mueller block (docs/model.md §5) per RGB channel: shape
    ``S + (3, 3, 3)``.

    ``normal_camera`` is the surface normal in the camera frame (x image right, y image up,
    z toward the camera), any non-zero length. With the rig's flash Stokes ``(1, 1, 0)`` the
    first column gives the observation channels: I^d = P[0,0] − P[1,1], I^s = P[1,1] + P[0,1],
    I^α = P[0,2].
    """
    shape, s, v = _batch(
        dict(eta=eta, sigma_s=sigma_s, sigma_ss=sigma_ss, rho_s=rho_s),
        dict(rho_ss=rho_ss, rho_d=rho_d, normal_camera=normal_camera),
    )
    out = _native.coaxial(
        s["eta"], s["sigma_s"], s["sigma_ss"], s["rho_s"], v["rho_ss"], v["rho_d"],
        v["normal_camera"],
    )
    return out.reshape(shape + (3, 3, 3))


def fresnel(eta: ArrayLike, theta_deg: ArrayLike) -> Dict[str, np.ndarray]:
    """The Fresnel terms of a dielectric (``ellipso model fresnel``): amplitudes ``rs``, ``rp``
    and the Mueller quantities ``r_plus``, ``r_minus``, ``r_cross``, ``t_plus``, ``t_minus``,
    each of the broadcast shape of ``eta`` (in [1, 10]) and ``theta_deg`` (in [0, 90])."""
    shape, s, _ = _batch(dict(eta=eta, theta_deg=theta_deg), {})
    out = _native.fresnel(s["eta"], s["theta_deg"])
    return {k: a.reshape(shape) for k, a in out.items()}
