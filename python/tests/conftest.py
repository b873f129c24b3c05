"""Paths of the tree under test: the source (models/), the build (the CLI).

scripts/test runs pytest with PYTHONPATH=<build>/python and
STIFFSIM_BUILD_DIR=<build>; by hand, the same two settings are all it needs.
"""

import os
import pathlib
import subprocess

import pytest

REPO = pathlib.Path(__file__).resolve().parents[2]
BUILD = pathlib.Path(os.environ.get("STIFFSIM_BUILD_DIR", REPO / "build")).resolve()
MODELS = REPO / "models"
CLI = BUILD / "apps" / "stiffsim"


@pytest.fixture(scope="session")
def models():
    return MODELS


@pytest.fixture(scope="session")
def cli():
    """Runs the built CLI: cli("run", scene, ...) -> CompletedProcess (text)."""
    if not CLI.exists():
        pytest.fail("the CLI is not built: %s (set STIFFSIM_BUILD_DIR)" % CLI)

    def run(*args, check=True):
        result = subprocess.run([str(CLI), *map(str, args)], capture_output=True, text=True)
        if check and result.returncode != 0:
            raise AssertionError("stiffsim %s failed (%d): %s" % (" ".join(map(str, args)),
                                                                 result.returncode, result.stderr))
        return result

    return run
