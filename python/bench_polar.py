"""Polarisation of a 2448×2048 mosaic from Python against the same work called from Rust;
writes docs/python-bench.md (a bench report, not a test).

Run from the repository root with the package installed (`python -m pip install ./python`):

    python -P python/bench_polar.py [--repeats 40] [--report docs/python-bench.md]

Python: `ellipso.polar(mosaic, layout=…, demosaic=…)` end to end (argument checks, the frame
checked in numpy's own buffer — no copy of the samples — the processing, the planes handed to
numpy, the result object). Rust: `ellipso_polar::process` of a frame, timed inside the same
extension build (`ellipso._native._bench_polar_rust`), so both sides run the same compiled code
and only the binding's cost differs — over a borrowed buffer (`RawFrameView::new`, as a Rust
caller holding a camera or file buffer does, and as Python does) and over a vector the caller
already owns (`RawFrame::new`: the other way a Rust caller holds samples).

Clock: the calling thread's CPU time (`CLOCK_THREAD_CPUTIME_ID`; `time.thread_time` in
Python), since the work runs on the calling thread in both cases and CPU time does not count
what other processes of a shared machine take; the least of `repeats` calls (in alternating
rounds of blocks, after two warm-up calls; medians and wall time beside it).
"""

import argparse
import os
import platform
import statistics
import time

import numpy as np

import ellipso
from ellipso import _native


#: Rounds of alternating blocks of calls.
ROUNDS = 4


def mosaic(h=2048, w=2448, seed=11):
    rng = np.random.default_rng(seed)
    return np.ascontiguousarray(rng.integers(200, 3800, size=(h, w), dtype=np.uint16))


def python_once(raw, layout, demosaic):
    c, t = time.thread_time(), time.perf_counter()
    r = ellipso.polar(raw, layout=layout, demosaic=demosaic)
    out = (time.thread_time() - c, time.perf_counter() - t)
    del r
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=40)
    ap.add_argument("--report", default="docs/python-bench.md")
    args = ap.parse_args()
    rows = []
    raw = mosaic()
    for layout, demosaic in (("mono", "superpixel"), ("mono", "bilinear"), ("colour", "superpixel")):
        _native._bench_polar_rust(raw, 2, layout=layout, demosaic=demosaic)
        for _ in range(2):
            python_once(raw, layout, demosaic)
        # rounds of blocks (each side's calls in a row, as a stream makes them: the allocator
        # settles into each side's pattern), alternated so that what else the machine runs
        # falls on both sides alike
        slice_, owned, py = [], [], []
        block = max(1, args.repeats // ROUNDS)
        for _ in range(ROUNDS):
            s, o = _native._bench_polar_rust(raw, block, layout=layout, demosaic=demosaic)
            slice_ += s
            owned += o
            py += [python_once(raw, layout, demosaic) for _ in range(block)]
        least = lambda v, k: min(x[k] for x in v) * 1e3  # noqa: E731
        med = lambda v, k: statistics.median(x[k] for x in v) * 1e3  # noqa: E731
        cpu = [least(v, 0) for v in (slice_, owned, py)]
        cpu_med = [med(v, 0) for v in (slice_, owned, py)]
        wall = [med(v, 1) for v in (slice_, owned, py)]
        rows.append((layout, demosaic, cpu, cpu_med, wall))
        print(f"{layout:6} {demosaic:10} CPU ms: rust {cpu[0]:.2f} (owned {cpu[1]:.2f}) python {cpu[2]:.2f}"
              f" → {cpu[2]/cpu[0]:.3f} ({cpu[2]/cpu[1]:.3f}); medians {cpu_med[0]:.2f} / {cpu_med[1]:.2f} / "
              f"{cpu_med[2]:.2f}; wall ms: {wall[0]:.2f} / {wall[1]:.2f} / {wall[2]:.2f}")
    lines = [
        "# Polarisation from Python against Rust (`python/bench_polar.py`)",
        "",
        "A 2448×2048 `uint16` mosaic (12-bit samples, seeded) through `ellipso.polar` from Python",
        "and through `ellipso_polar::process` from Rust, in the same build of the extension",
        "(`ellipso._native._bench_polar_rust`): the difference is what the binding costs (argument",
        "checks, the planes handed to numpy, the result object). Python reads the `uint16` array in",
        "place (a `RawFrameView` over numpy's buffer: the samples are never copied); Rust starts from",
        "a borrowed buffer the same way (`RawFrameView::new`, as a caller holding a camera or file",
        "buffer does) or from a vector it owns (`RawFrame::new`); neither copies the samples.",
        "",
        "Clock: the calling thread's CPU time (`CLOCK_THREAD_CPUTIME_ID`, `time.thread_time`): the",
        "work runs on the calling thread on both sides, and on a shared machine CPU time does not",
        "count what other processes take. The figure is the least CPU time of "
        f"{args.repeats} calls of each",
        f"({ROUNDS} alternating rounds of blocks of calls, after two warm-up calls): the call least",
        "disturbed by the caches and cores other processes share; medians in brackets, wall-clock",
        "medians for reference; one thread (the processing is serial).",
        "",
        "| layout | demosaic | Rust, borrowed buffer | Rust, owned vector | Python | Python / Rust (borrowed) | Python / Rust (owned) | wall: Rust borrowed / owned / Python |",
        "|---|---|---:|---:|---:|---:|---:|---:|",
    ]
    for l, d, c, m, w in rows:
        lines.append(
            f"| {l} | {d} | {c[0]:.2f} ({m[0]:.2f}) ms | {c[1]:.2f} ({m[1]:.2f}) ms | "
            f"{c[2]:.2f} ({m[2]:.2f}) ms | {c[2]/c[0]:.3f} | {c[2]/c[1]:.3f} | "
            f"{w[0]:.1f} / {w[1]:.1f} / {w[2]:.1f} ms |"
        )
    lines += [
        "",
        f"Machine: {platform.system()} {platform.machine()}, {os.cpu_count()} CPUs shared with other "
        f"work (load average {os.getloadavg()[0]:.1f} at the end), Python "
        f"{platform.python_version()}, numpy {np.__version__}, ellipso {ellipso.__version__} "
        "(release build of the extension).",
        "",
        "Reproduce: `python -m pip install ./python && python -P python/bench_polar.py` (`-P`: the installed package, not the source folder `python/ellipso` beside the script).",
        "",
    ]
    with open(args.report, "w", encoding="utf-8") as f:
        f.write("\n".join(lines))
    print(f"wrote {args.report}")


if __name__ == "__main__":
    main()
