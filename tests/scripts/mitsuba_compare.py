#!/usr/bin/env python3
"""Render an `ellipso export mitsuba` directory in Mitsuba 3 and compare it with ellipso's own
render of the same view (`ellipso-s0.exr`, read with the OpenEXR bindings).

Usage: mitsuba_compare.py EXPORT_DIR [--spp N] [--variant V] [--figure OUT.png]
                          [--check-exr FILE CHANNEL ...]

Prints one JSON object: the relative RMSE sqrt(sum (mitsuba - ellipso)^2 / sum ellipso^2) over
the R, G, B channels of the pixels both renderers cover fully (ellipso's A = 1, Mitsuba's alpha
= 1, shrunk by one pixel so edge pixels, which Mitsuba averages over their area and ellipso
samples at their centre, are left out), the pixel count, and for each --check-exr file the
channels it holds (the EXR read-back check of ellipso's other float outputs).
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
    a = ap.parse_args()

    import mitsuba as mi

    mi.set_variant(a.variant)
    mi.set_log_level(mi.LogLevel.Warn)
    scene = mi.load_file(os.path.join(a.export_dir, "scene.xml"), spp=a.spp)
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
    }
    if a.figure:
        figure(a.figure, ellipso_rgb, mitsuba_rgb, mask, rmse, f"{a.variant}, {a.spp} spp")
    print(json.dumps(result))


if __name__ == "__main__":
    main()
