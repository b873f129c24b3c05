"""Pictures of a run: Scene.drawing and scripts/render on a short rope run."""

import os
import pathlib
import subprocess
import sys

import numpy as np
import pytest

import stiffsim

REPO = pathlib.Path(__file__).resolve().parents[2]
BUILD = pathlib.Path(os.environ.get("STIFFSIM_BUILD_DIR", REPO / "build")).resolve()
RENDER = REPO / "scripts" / "render"
ROPE_SMALL = ["--set", "rope.nodes=20"]


def render(*args, env=None):
    """scripts/render under this interpreter (the build's) -> CompletedProcess."""
    environment = dict(os.environ, STIFFSIM_BUILD_DIR=str(BUILD))
    environment.update(env or {})
    return subprocess.run([sys.executable, str(RENDER), *map(str, args)], capture_output=True,
                          text=True, env=environment)


@pytest.fixture(scope="module")
def rope_run(tmp_path_factory):
    """A 0.2 s run of a 20-node rope: (scene file, CSV)."""
    cli = BUILD / "apps" / "stiffsim"
    if not cli.exists():
        pytest.fail("the CLI is not built: %s (set STIFFSIM_BUILD_DIR)" % cli)
    csv = tmp_path_factory.mktemp("render") / "rope.csv"
    subprocess.run([str(cli), "run", str(REPO / "models" / "rope.yaml"), *ROPE_SMALL,
                    "--t-final", "0.2", "-q", "--output", str(csv)], check=True)
    return REPO / "models" / "rope.yaml", csv


def test_drawing_points_are_the_state_and_the_pins():
    scene = stiffsim.load_scene(REPO / "models" / "rope.yaml", {"rope.nodes": 5})
    sim = stiffsim.Simulator(scene, step=1e-3, fixed_step=True)
    sim.advance_to(0.01)
    (rope,) = scene.drawing(sim.t, sim.x)
    assert rope["name"] == "rope"
    assert rope["points"].shape == (5, 3)
    np.testing.assert_array_equal(rope["points"][1:].ravel(), sim.q)
    np.testing.assert_array_equal(rope["points"][0], [0.0, 0.0, 0.0])  # the pinned node
    assert rope["segments"].tolist() == [[0, 1], [1, 2], [2, 3], [3, 4]]
    assert rope["fixed"].tolist() == [0]
    with pytest.raises(stiffsim.InputError, match="state of size 3, expected 24"):
        scene.drawing(0.0, np.zeros(3))


def test_render_writes_a_png(rope_run, tmp_path):
    scene, csv = rope_run
    out = tmp_path / "rope.png"
    result = render(scene, csv, *ROPE_SMALL, "--out", out, "--times", "0,0.1,0.2")
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip() == str(out)
    data = out.read_bytes()
    assert data.startswith(b"\x89PNG\r\n\x1a\n")
    assert len(data) > 5000  # axes, legend and three ropes, not an empty canvas


def test_render_rejects_a_missing_csv(rope_run, tmp_path):
    scene, _ = rope_run
    missing = tmp_path / "missing.csv"
    result = render(scene, missing, "--out", tmp_path / "x.png")
    assert result.returncode != 0
    assert str(missing) in result.stderr
    assert not (tmp_path / "x.png").exists()


def test_render_rejects_a_csv_of_another_scene(rope_run, tmp_path):
    scene, csv = rope_run
    # Without the run's --set the scene has 50 nodes: other columns.
    result = render(scene, csv, "--out", tmp_path / "x.png")
    assert result.returncode != 0
    assert str(csv) in result.stderr
    assert "columns do not match" in result.stderr
    assert not (tmp_path / "x.png").exists()


def test_render_says_when_matplotlib_is_missing(rope_run, tmp_path):
    scene, csv = rope_run
    # A matplotlib that cannot be imported, first on the path; no re-run
    # under another interpreter (which would have the real one).
    (tmp_path / "matplotlib.py").write_text("raise ImportError('hidden by the test')\n")
    path = os.pathsep.join([str(tmp_path), os.environ.get("PYTHONPATH", "")])
    result = render(scene, csv, *ROPE_SMALL, "--out", tmp_path / "x.png",
                    env={"PYTHONPATH": path, "STIFFSIM_RENDER_REEXEC": "1"})
    assert result.returncode != 0
    assert "matplotlib" in result.stderr
    assert "Traceback" not in result.stderr
