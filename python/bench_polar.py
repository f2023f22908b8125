"""Polarisation of a 2448×2048 mosaic from Python against the same work called from Rust;
writes docs/python-bench.md (a bench report, not a test).

Run from the repository root with the package installed (`python -m pip install ./python`):

    python python/bench_polar.py [--repeats 30] [--report docs/python-bench.md]

Python: `ellipso.polar(mosaic, layout=…, demosaic=…)` end to end (argument checks, the copy of
the samples into the crate's frame, the processing, the planes handed to numpy, the result
object). Rust: `RawFrame::new` + `ellipso_polar::process` on a vector the caller already owns,
timed inside the same extension build (`ellipso._native._bench_polar_rust`), so both sides run
the same compiled code and only the binding's cost differs. Medians of `repeats` calls after
two warm-up calls; the ratio is Python's median over Rust's.
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


def time_python(raw, layout, demosaic, repeats):
    for _ in range(2):
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
        rust = _native._bench_polar_rust(raw, args.repeats, layout=layout, demosaic=demosaic)
        py = time_python(raw, layout, demosaic, args.repeats)
        r_med, p_med = statistics.median(rust), statistics.median(py)
        rows.append((layout, demosaic, r_med * 1e3, p_med * 1e3, p_med / r_med))
        print(f"{layout:6} {demosaic:10} rust {r_med*1e3:7.2f} ms  python {p_med*1e3:7.2f} ms  ratio {p_med/r_med:.3f}")
    cpu = platform.processor() or platform.machine()
    lines = [
        "# Polarisation from Python against Rust (`python/bench_polar.py`)",
        "",
        "A 2448×2048 `uint16` mosaic (12-bit samples, seeded) through `ellipso.polar` from Python",
        "and through `RawFrame::new` + `ellipso_polar::process` from Rust, in the same build of the",
        "extension (`ellipso._native._bench_polar_rust`): the difference is what the binding costs",
        "(checks, one copy of the samples into the crate's frame, the planes handed to numpy, the",
        "result object). Medians of "
        f"{args.repeats} calls after two warm-up calls, one thread (the processing is serial).",
        "",
        "| layout | demosaic | Rust, ms | Python, ms | Python / Rust |",
        "|---|---|---:|---:|---:|",
    ]
    lines += [f"| {l} | {d} | {r:.2f} | {p:.2f} | {q:.3f} |" for l, d, r, p, q in rows]
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
