"""Shared fixtures: the `ellipso` binary and a tiny simulated session with its fit.

The session and the fit are made by the command line the package mirrors: `ellipso capture`
on the shipped sphere scene (16 photos at 640×480, enough for every frame to be posed) and
`ellipso fit` on it (300 vertices, one outer iteration). The binary is `$ELLIPSO_BIN`, else
`target/release/ellipso` or `target/debug/ellipso` of this checkout, else `ellipso` on PATH;
tests that need it are skipped without one unless `$ELLIPSO_BIN` is set (CI sets it, so there
they run or fail).
"""

import os
import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


def _binary():
    given = os.environ.get("ELLIPSO_BIN")
    if given:
        if not os.access(given, os.X_OK):
            pytest.fail(f"ELLIPSO_BIN={given} is not an executable")
        return given
    for profile in ("release", "debug"):
        p = ROOT / "target" / profile / "ellipso"
        if p.exists():
            return str(p)
    return shutil.which("ellipso")


@pytest.fixture(scope="session")
def ellipso_bin():
    b = _binary()
    if b is None:
        pytest.skip("no `ellipso` binary (build it with cargo, or set ELLIPSO_BIN)")
    return b


def run_cli(binary, *args):
    """Runs the CLI; fails the test with its stderr on a non-zero exit."""
    p = subprocess.run([binary, *map(str, args)], capture_output=True, text=True)
    if p.returncode != 0:
        pytest.fail(f"ellipso {' '.join(map(str, args))} failed ({p.returncode}):\n{p.stderr}")
    return p


@pytest.fixture(scope="session")
def session_dir(ellipso_bin, tmp_path_factory):
    d = tmp_path_factory.mktemp("capture") / "session"
    run_cli(
        ellipso_bin, "capture", "--sim", ROOT / "sim/scenes/sphere.toml", "--out", d,
        "--photos", 16, "--resolution", "640x480",
    )
    return d


@pytest.fixture(scope="session")
def fit_dir(ellipso_bin, session_dir, tmp_path_factory):
    d = tmp_path_factory.mktemp("fit") / "fit"
    run_cli(ellipso_bin, "fit", session_dir, "--out", d, "--vertices", 300, "--outer", 1)
    return d
