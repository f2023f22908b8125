#!/usr/bin/env python3
"""Render an `ellipso export mitsuba` directory in Mitsuba 3 and compare it with ellipso's own
render of the same view (`ellipso-s0.exr`, `ellipso-stokes.exr`, read with the OpenEXR bindings).

Usage: mitsuba_compare.py EXPORT_DIR [--spp N] [--variant V] [--figure OUT.png]
                          [--check-exr FILE CHANNEL ...]

RGB variants (`scalar_rgb`, …) render `scene-rgb.xml` and compare R, G, B with `ellipso-s0.exr`.
Polarised variants (`*_polarized`) render `scene.xml` (the `stokes` integrator) and compare
Mitsuba's S0, S1, S2 with `ellipso-stokes.exr` in luminance Y = 0.2126 R + 0.7152 G + 0.0722 B
(mono variants render Y themselves; spectral ones upsample the RGB albedos to spectra and back
to sRGB, which shifts hues by a few percent: their per-channel S0 error is reported beside).

Prints one JSON object: the relative RMSE sqrt(sum (mitsuba - ellipso)^2 / sum ellipso^2) of S0
(`relative_rmse`) and, polarised, of the polarised part (S1, S2) together
(`relative_rmse_polarised`) and of S2 alone, over the pixels both renderers cover fully
(ellipso's A = 1, Mitsuba's alpha = 1, shrunk by one pixel so edge pixels, which Mitsuba averages
over their area and ellipso samples at their centre, are left out), the pixel count, and for
each --check-exr file the channels it holds (the EXR read-back check of ellipso's other float
outputs).
"""
import argparse
import json
import os
import sys

import numpy as np
import OpenEXR


def read_exr(path):
    """Channel name -> float32 array (rows, columns), each channel on its own."""
    with OpenEXR.File(path, separate_channels=True) as f:
        return {name: np.asarray(ch.pixels, dtype=np.float32) for name, ch in f.channels().items()}


def shrink(mask):
    """The mask minus every pixel with an uncovered 4-neighbour."""
    m = mask.copy()
    m[1:, :] &= mask[:-1, :]
    m[:-1, :] &= mask[1:, :]
    m[:, 1:] &= mask[:, :-1]
    m[:, :-1] &= mask[:, 1:]
    m[0, :] = m[-1, :] = False
    m[:, 0] = m[:, -1] = False
    return m


def figure(path, ellipso, mitsuba, mask, rmse, label):
    """ellipso | Mitsuba | difference, 3x enlarged, with a two-line title (needs Pillow)."""
    from PIL import Image, ImageDraw

    scale = np.percentile(ellipso[mask], 99.5) if mask.any() else 1.0
    scale = max(scale, 1e-12)

    def tone(rgb):
        return (np.clip(rgb / scale, 0, 1) ** (1 / 2.2) * 255).astype(np.uint8)

    span = 0.02  # the difference map's range: +-2 % of the highlight
    d = np.clip(np.mean(mitsuba - ellipso, axis=2) / scale / span, -1, 1)
    diff_rgb = np.stack(
        [np.where(d > 0, 1.0, 1.0 + d), 1.0 - np.abs(d), np.where(d < 0, 1.0, 1.0 - d)], axis=2
    )
    diff_rgb = (diff_rgb * 255).astype(np.uint8)
    diff_rgb[~mask] = 60
    gap = np.full((ellipso.shape[0], 3, 3), 24, np.uint8)
    row = np.concatenate([tone(ellipso), gap, tone(mitsuba), gap, diff_rgb], axis=1)
    row = row.repeat(3, axis=0).repeat(3, axis=1)
    img = Image.new("RGB", (row.shape[1], row.shape[0] + 30), (24, 24, 24))
    img.paste(Image.fromarray(row), (0, 30))
    draw = ImageDraw.Draw(img)
    draw.text((4, 2), f"ellipso (rho_ss off)  |  Mitsuba 3 pplastic ({label})  |  difference", fill=(240, 240, 240))
    draw.text(
        (4, 15),
        f"relative RMSE {rmse:.4f} over {int(mask.sum())} px;  difference: blue -2 % .. red +2 % of the highlight; grey: not compared",
        fill=(200, 200, 200),
    )
    img.save(path)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("export_dir")
    ap.add_argument("--spp", type=int, default=64)
    ap.add_argument("--variant", default="scalar_rgb")
    ap.add_argument("--figure")
    ap.add_argument("--check-exr", nargs="+", default=[])
    ap.add_argument("--check-ply", help="a fit.ply to read with plyfile: its vertex properties and types")
    a = ap.parse_args()

    if a.variant.startswith("llvm") and "DRJIT_LIBLLVM_PATH" not in os.environ:
        # Dr.Jit's LLVM back end emits instructions LLVM < 17 cannot select (fminimum):
        # take the newest libLLVM the system has (Debian: libllvm19)
        import glob
        import re

        def version(path):
            m = re.search(r"LLVM[-.](?:so\.)?(\d+)", os.path.basename(path))
            return int(m.group(1)) if m else 0

        found = sorted(glob.glob("/usr/lib/*/libLLVM*.so*") + glob.glob("/usr/lib/llvm-*/lib/libLLVM*.so*"), key=version)
        if found and version(found[-1]) >= 17:
            os.environ["DRJIT_LIBLLVM_PATH"] = found[-1]
    import mitsuba as mi

    mi.set_variant(a.variant)
    # warnings (a specular albedo above 1 in a bitmap) go to stdout, where the JSON goes
    mi.set_log_level(mi.LogLevel.Error)
    if "polarized" in a.variant:
        return stokes_main(a, mi)
    scene = mi.load_file(os.path.join(a.export_dir, "scene-rgb.xml"), spp=a.spp)
    image = np.asarray(mi.render(scene, seed=1), dtype=np.float64)
    mitsuba_rgb, mitsuba_alpha = image[..., :3], image[..., 3]

    ref = read_exr(os.path.join(a.export_dir, "ellipso-s0.exr"))
    ellipso_rgb = np.stack([ref["R"], ref["G"], ref["B"]], axis=2).astype(np.float64)
    if ellipso_rgb.shape != mitsuba_rgb.shape:
        sys.exit(f"image sizes differ: ellipso {ellipso_rgb.shape}, mitsuba {mitsuba_rgb.shape}")
    mask = shrink((ref["A"] == 1.0) & (mitsuba_alpha > 0.999))
    e, m = ellipso_rgb[mask], mitsuba_rgb[mask]
    rmse = float(np.sqrt(np.sum((m - e) ** 2) / max(np.sum(e ** 2), 1e-300)))
    result = {
        "relative_rmse": rmse,
        "pixels": int(mask.sum()),
        "mean_ratio_mitsuba_over_ellipso": float(m.sum() / max(e.sum(), 1e-300)),
        "variant": a.variant,
        "spp": a.spp,
        "exr_channels": {p: sorted(read_exr(p).keys()) for p in a.check_exr},
        "ply": check_ply(a.check_ply),
    }
    if a.figure:
        figure(a.figure, ellipso_rgb, mitsuba_rgb, mask, rmse, f"{a.variant}, {a.spp} spp")
    print(json.dumps(result))


def check_ply(path):
    """plyfile's view of a fit.ply: vertex property name -> numpy dtype, and the first row."""
    if not path:
        return None
    from plyfile import PlyData

    v = PlyData.read(path)["vertex"]
    return {
        "types": {p.name: str(v.data.dtype[p.name]) for p in v.properties},
        "rows": int(v.count),
        "first": {p.name: float(v.data[p.name][0]) for p in v.properties},
    }


def rel_rmse(m, e):
    return float(np.sqrt(np.sum((m - e) ** 2) / max(np.sum(e ** 2), 1e-300)))


def stokes_main(a, mi):
    """The polarised comparison (module doc)."""
    scene = mi.load_file(os.path.join(a.export_dir, "scene.xml"), spp=a.spp)
    mi.render(scene, seed=1)
    bitmap = scene.sensors()[0].film().bitmap(raw=False)
    channels = {name: np.asarray(b, dtype=np.float64) for name, b in bitmap.split()}
    # mono variants name the Stokes AOVs S0.R.. too (every entry the mono value)
    mitsuba = {k: channels[k][..., 0] if channels[k].ndim == 3 else channels[k] for k in
               [f"S{i}.{c}" for i in range(3) for c in "RGB"] if k in channels}
    if not mitsuba:
        # a bitmap that keeps the AOVs as multi-channel layers: S0 -> (h, w, 3)
        for i in range(3):
            arr = channels[f"S{i}"]
            for j, c in enumerate("RGB"):
                mitsuba[f"S{i}.{c}"] = arr[..., j]
    # Mitsuba's coverage: the root layer's alpha where it has one (spectral: RGBA; mono
    # variants keep only Y, and then ellipso's shrunk coverage alone decides)
    root = channels.get("<root>")
    alpha = root[..., -1] if root is not None and root.ndim == 3 and root.shape[2] in (2, 4) else None
    ref = read_exr(os.path.join(a.export_dir, "ellipso-stokes.exr"))
    mono = "mono" in a.variant
    weights = {"R": 0.2126, "G": 0.7152, "B": 0.0722}

    def ellipso(i):
        if mono:
            return sum(w * ref[f"S{i}.{c}"] for c, w in weights.items())[..., None].astype(np.float64)
        return np.stack([ref[f"S{i}.{c}"] for c in "RGB"], axis=2).astype(np.float64)

    def mits(i):
        if mono:
            return mitsuba[f"S{i}.R"][..., None]
        return np.stack([mitsuba[f"S{i}.{c}"] for c in "RGB"], axis=2)

    e = [ellipso(i) for i in range(3)]
    m = [mits(i) for i in range(3)]
    per_channel = None
    if not mono:
        # spectral variants upsample the RGB albedos to spectra and turn the result back into
        # sRGB, which shifts hues by a few percent: the check is on luminance, the per-channel
        # figure is reported beside it
        lum = lambda x: (0.2126 * x[..., 0] + 0.7152 * x[..., 1] + 0.0722 * x[..., 2])[..., None]
        per_channel = (e, m)
        e = [lum(x) for x in e]
        m = [lum(x) for x in m]
    if e[0].shape[:2] != m[0].shape[:2]:
        sys.exit(f"image sizes differ: ellipso {e[0].shape}, mitsuba {m[0].shape}")
    covered = ref["A"] == 1.0
    if alpha is not None:
        covered &= alpha > 0.999
    mask = shrink(covered)
    s0 = rel_rmse(m[0][mask], e[0][mask])
    pol_m = np.concatenate([m[1][mask], m[2][mask]])
    pol_e = np.concatenate([e[1][mask], e[2][mask]])
    result = {
        "relative_rmse": s0,
        "relative_rmse_polarised": rel_rmse(pol_m, pol_e),
        "relative_rmse_s1": rel_rmse(m[1][mask], e[1][mask]),
        "relative_rmse_s2": rel_rmse(m[2][mask], e[2][mask]),
        "mean_dolp_ellipso": float(np.mean(np.hypot(e[1][mask], e[2][mask]) / np.maximum(e[0][mask], 1e-30))),
        "mean_dolp_mitsuba": float(np.mean(np.hypot(m[1][mask], m[2][mask]) / np.maximum(m[0][mask], 1e-30))),
        "pixels": int(mask.sum()),
        "compared": "luminance Y" if not mono else "mono",
        "relative_rmse_rgb": None if per_channel is None else rel_rmse(per_channel[1][0][mask], per_channel[0][0][mask]),
        "variant": a.variant,
        "spp": a.spp,
        "channels": {k: list(v.shape) for k, v in channels.items()},
        "alpha_covered": None if alpha is None else int((alpha > 0.999).sum()),
        "exr_channels": {p: sorted(read_exr(p).keys()) for p in a.check_exr},
    }
    if a.figure:
        figure(a.figure, np.repeat(e[0], 3, axis=2), np.repeat(m[0], 3, axis=2), mask, s0,
               f"{a.variant}, {a.spp} spp, S0")
    print(json.dumps(result))


if __name__ == "__main__":
    main()
