"""Shared fixtures: the `ellipso` binary and the demo's session and fit.

The session and the fit are the quick demo's, made by the command line the package mirrors:
`ellipso demo --quick` (the glass sphere scene at quarter resolution, 612×512, 24 photos:
capture, tracking, carving, fit; about a minute with a debug binary). The binary is
`$ELLIPSO_BIN`, else
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
def demo_dir(ellipso_bin, tmp_path_factory):
    d = tmp_path_factory.mktemp("demo") / "demo"
    run_cli(ellipso_bin, "demo", "--quick", "--out", d, "--scene", ROOT / "sim/scenes/sphere.toml")
    return d


@pytest.fixture(scope="session")
def session_dir(demo_dir):
    return demo_dir / "session"


@pytest.fixture(scope="session")
def fit_dir(demo_dir):
    return demo_dir / "fit"
