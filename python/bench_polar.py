"""Polarisation of a 2448×2048 mosaic from Python against the same work called from Rust;
writes docs/python-bench.md (a bench report, not a test).

Run from the repository root with the package installed (`python -m pip install ./python`):

    python python/bench_polar.py [--repeats 30] [--report docs/python-bench.md]

Python: `ellipso.polar(mosaic, layout=…, demosaic=…)` end to end (argument checks, the copy of
the samples into the crate's frame, the processing, the planes handed to numpy, the result
object). Rust: `RawFrame::new` + `ellipso_polar::process`, timed inside the same extension
build (`ellipso._native._bench_polar_rust`), so both sides run the same compiled code and only
the binding's cost differs — from a borrowed buffer (the samples copied into the frame, as a
Rust caller holding a camera or file buffer does, and as Python does) and from a vector the
caller already owns (no copy: the strictest baseline). Medians of `repeats` calls after two
warm-up calls; the ratios are Python's median over each Rust median.
"""

import argparse
import os
import platform
import statistics
import time

import numpy as np

import ellipso
from ellipso import _native


def mosaic(layout, h=2048, w=2448, seed=11):
    rng = np.random.default_rng(seed)
    raw = rng.integers(200, 3800, size=(h, w), dtype=np.uint16)
    return np.ascontiguousarray(raw)


def time_python(raw, layout, demosaic, repeats, warm=True):
    for _ in range(2 if warm else 0):
        ellipso.polar(raw, layout=layout, demosaic=demosaic)
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        r = ellipso.polar(raw, layout=layout, demosaic=demosaic)
        times.append(time.perf_counter() - t)
        del r
    return times


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=30)
    ap.add_argument("--report", default="docs/python-bench.md")
    args = ap.parse_args()
    rows = []
    for layout, demosaic in (("mono", "superpixel"), ("mono", "bilinear"), ("colour", "superpixel")):
        raw = mosaic(layout)
        _native._bench_polar_rust(raw, 2, layout=layout, demosaic=demosaic)
        time_python(raw, layout, demosaic, 0)
        # interleaved, so a busy machine slows both sides alike
        rust_slice, rust_owned, py = [], [], []
        for _ in range(args.repeats):
            s, o = _native._bench_polar_rust(raw, 1, layout=layout, demosaic=demosaic)
            rust_slice += s
            rust_owned += o
            py += time_python(raw, layout, demosaic, 1, warm=False)
        rs, ro, p = (statistics.median(v) * 1e3 for v in (rust_slice, rust_owned, py))
        rows.append((layout, demosaic, rs, ro, p, p / rs, p / ro))
        print(f"{layout:6} {demosaic:10} rust {rs:7.2f} ms (owned {ro:7.2f})  python {p:7.2f} ms  "
              f"ratio {p/rs:.3f} (owned {p/ro:.3f})")
    cpu = platform.processor() or platform.machine()
    lines = [
        "# Polarisation from Python against Rust (`python/bench_polar.py`)",
        "",
        "A 2448×2048 `uint16` mosaic (12-bit samples, seeded) through `ellipso.polar` from Python",
        "and through `RawFrame::new` + `ellipso_polar::process` from Rust, in the same build of the",
        "extension (`ellipso._native._bench_polar_rust`): the difference is what the binding costs",
        "(checks, one copy of the samples into the crate's frame, the planes handed to numpy, the",
        "result object). Rust starts from a borrowed buffer, copying it into the frame as Python",
        "does (a Rust caller holding a camera or file buffer does the same), or from a vector it",
        "already owns (the strictest baseline). Medians of "
        f"{args.repeats} calls of each, interleaved, after two warm-up calls; one thread (the",
        "processing is serial).",
        "",
        "| layout | demosaic | Rust, borrowed buffer, ms | Rust, owned vector, ms | Python, ms | Python / Rust (borrowed) | Python / Rust (owned) |",
        "|---|---|---:|---:|---:|---:|---:|",
    ]
    lines += [
        f"| {l} | {d} | {rs:.2f} | {ro:.2f} | {p:.2f} | {q1:.3f} | {q2:.3f} |"
        for l, d, rs, ro, p, q1, q2 in rows
    ]
    lines += [
        "",
        f"Machine: {platform.system()} {cpu}, {os.cpu_count()} CPUs (shared), Python "
        f"{platform.python_version()}, numpy {np.__version__}, ellipso {ellipso.__version__} "
        "(release wheel).",
        "",
        "Reproduce: `python -m pip install ./python && python python/bench_polar.py`.",
        "",
    ]
    with open(args.report, "w", encoding="utf-8") as f:
        f.write("\n".join(lines))
    print(f"wrote {args.report}")


if __name__ == "__main__":
    main()
