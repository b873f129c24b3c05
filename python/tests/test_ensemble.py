"""bench/ensemble.py: perturbed starts, alternation, the figures it reads."""

import json
import pathlib
import subprocess
import sys

import pytest

from conftest import CLI, MODELS, REPO

ENSEMBLE = REPO / "bench" / "ensemble.py"
# A small sheet, a few steps: each run takes a fraction of a second.
RUN = [str(MODELS / "cloth.yaml"), "--set", "cloth.nodes=[6,6]", "--fixed-step", "--step", "0.01",
       "--t-final", "0.05"]


def ensemble(*args):
    return subprocess.run([sys.executable, str(ENSEMBLE), *map(str, args)], capture_output=True,
                          text=True)


@pytest.fixture
def built():
    if not CLI.exists():
        pytest.fail("the CLI is not built: %s (set STIFFSIM_BUILD_DIR)" % CLI)


def test_runs_each_start_with_both_binaries(built, tmp_path, cli):
    out = tmp_path / "ensemble.json"
    result = ensemble("--runs", 3, "--vs", CLI, "--json", out, CLI, *RUN)
    assert result.returncode == 0, result.stderr
    report = json.loads(out.read_text())
    accuracies = [r["accuracy"] for r in report["binaries"]["A"]["runs"]]
    # The starts differ by 1e-7 of the accuracy, the same for both binaries.
    assert accuracies == pytest.approx([1e-3, 1e-3 * (1 + 1e-7), 1e-3 * (1 + 2e-7)], rel=1e-15)
    assert len(set(accuracies)) == 3
    assert [r["accuracy"] for r in report["binaries"]["B"]["runs"]] == accuracies
    # The figures are those of the run's own statistics.
    stats_path = tmp_path / "one.json"
    cli("run", *RUN, "-q", "--accuracy", repr(accuracies[0]), "--stats", stats_path)
    stats = json.loads(stats_path.read_text())["statistics"]
    first = report["binaries"]["A"]["runs"][0]
    assert first["newton_iterations"] == stats["newton_raphson_iterations"]
    assert first["halvings"] == stats["substep_failures"]
    ratio = report["paired_ratio"]
    assert ratio["min"] <= ratio["median"] <= ratio["max"]
    assert "paired ratio A/B" in result.stdout


def test_refuses_what_it_sets_itself(built, tmp_path):
    result = ensemble("--runs", 2, CLI, *RUN, "--accuracy", "1e-4")
    assert result.returncode == 2
    assert "--accuracy is set by the ensemble" in result.stderr
    result = ensemble("--runs", 2, CLI, *RUN, "--stats=s.json")
    assert result.returncode == 2
    assert "--stats is set by the ensemble" in result.stderr


def test_a_failed_run_stops_it_and_writes_nothing(built, tmp_path):
    out = tmp_path / "ensemble.json"
    result = ensemble("--runs", 2, "--json", out, CLI, *RUN, "--set", "cloth.nodes=[1,6]")
    assert result.returncode != 0
    assert "exited with 2" in result.stderr
    assert not out.exists()
    assert not pathlib.Path(str(out) + ".partial").exists()
