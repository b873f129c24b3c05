"""The Python module against the CLI: same scenes, same numbers, same errors."""

import csv
import json
import os
import signal
import subprocess
import sys
import textwrap
import time

import numpy as np
import pytest

import stiffsim

ROPE_SMALL = {"rope.nodes": 20}  # 19 free nodes: fast, still stiff (k = 1e5)


def read_csv(path):
    """Header and rows of a trajectory CSV; the CLI writes shortest round-trip
    numbers, so float() gives back the very doubles it had."""
    with open(path, newline="") as f:
        rows = [row for row in csv.reader(f) if row and not row[0].startswith("#")]
    return rows[0], np.array([[float(x) for x in row] for row in rows[1:]])


def cli_error(result):
    assert result.stderr.startswith("stiffsim: error: "), result.stderr
    return result.stderr.splitlines()[0][len("stiffsim: error: "):]


def test_load_scene_names_match_the_csv_header(models, cli, tmp_path):
    scene = stiffsim.load_scene(models / "rope.yaml")
    assert scene.name == "rope"
    assert scene.components == ["rope"]
    # 50 nodes, node 0 pinned: 49 free nodes in 3-D.
    assert scene.dofs == {"nq": 147, "nv": 147, "nz": 0}
    assert len(scene.position_names) == 147 and len(scene.velocity_names) == 147
    out = tmp_path / "rope.csv"
    cli("run", models / "rope.yaml", "--t-final", "0.01", "-q", "--output", out)
    header, _ = read_csv(out)
    assert scene.columns == header
    assert header[0] == "t" and header[1] == "q:" + scene.position_names[0]


def test_overrides_use_the_keys_of_set(models):
    scene = stiffsim.load_scene(models / "rope.yaml",
                                overrides={"rope.nodes": 20, "simulation.t_final": 0.25,
                                           "simulation.accuracy": 1e-5, "gravity": [0, 0, -1]})
    assert scene.dofs["nq"] == 19 * 3
    assert scene.t_final == 0.25
    assert scene.accuracy == 1e-5
    with pytest.raises(stiffsim.InputError, match="rope"):
        stiffsim.load_scene(models / "rope.yaml", overrides={"rope.nodez": 20})


@pytest.mark.parametrize("scene_file, overrides, options", [
    ("rope.yaml", ROPE_SMALL, {"integrator": "vie", "step": 1e-3, "fixed_step": True}),
    ("rope.yaml", ROPE_SMALL, {"integrator": "rk45", "accuracy": 1e-4}),
    ("chain10.yaml", None, {"integrator": "vie", "accuracy": 1e-3}),
    # A free box hung on a rope: an attachment through a floating joint.
    ("box_on_rope.yaml", None, {"integrator": "vie", "step": 1e-3, "fixed_step": True}),
])
def test_steps_equal_the_cli_trajectory_bit_for_bit(models, cli, tmp_path, scene_file, overrides,
                                                    options):
    t_final = 0.1
    sets = []
    for key, value in (overrides or {}).items():
        sets += ["--set", "%s=%s" % (key, json.dumps(value))]
    flags = []
    for key, value in options.items():
        flag = "--" + key.replace("_", "-")
        flags += [flag] if value is True else [flag, str(value)]
    out = tmp_path / "cli.csv"
    # Sample period 0: one row per step, no dense output in between.
    cli("run", models / scene_file, *sets, *flags, "--t-final", t_final, "--sample-period", 0,
        "-q", "--output", out)
    _, expected = read_csv(out)

    sim = stiffsim.Simulator(stiffsim.load_scene(models / scene_file, overrides), **options)
    rows = [np.concatenate([[sim.t], sim.x])]
    while sim.t < t_final:
        sim.step(t_final)
        rows.append(np.concatenate([[sim.t], sim.x]))
    got = np.array(rows)
    assert got.shape == expected.shape
    assert len(got) > 10
    np.testing.assert_array_equal(got, expected)  # exact: same library, same doubles

    again = stiffsim.Simulator(stiffsim.load_scene(models / scene_file, overrides), **options)
    assert again.advance_to(t_final) == t_final
    np.testing.assert_array_equal(again.x, expected[-1, 1:])


def test_state_arrays_are_copies_and_setting_restarts(models):
    sim = stiffsim.Simulator(stiffsim.load_scene(models / "chain10.yaml"), step=1e-3,
                             fixed_step=True)
    nq = sim.scene.dofs["nq"]
    assert sim.q.shape == (nq,) and sim.v.shape == (nq,) and sim.z.shape == (0,)
    assert sim.q.dtype == np.float64
    np.testing.assert_array_equal(sim.q, np.full(nq, 0.3))  # initial: {all_joints: 0.3}
    q = sim.q
    q[:] = 0.0
    assert sim.q[0] == 0.3  # the array read was a copy

    sim.advance_to(0.01)
    assert sim.stats["steps_taken"] == 10
    sim.q = np.zeros(nq)
    sim.v = np.ones(nq)
    np.testing.assert_array_equal(sim.q, np.zeros(nq))
    np.testing.assert_array_equal(sim.v, np.ones(nq))
    assert sim.t == pytest.approx(0.01)
    assert sim.stats["steps_taken"] == 0  # restarted
    sim.step()
    assert sim.t == pytest.approx(0.011)
    with pytest.raises(stiffsim.InputError, match="q: expected 10 values, got 3"):
        sim.q = np.zeros(3)


def test_stats_have_the_names_and_counts_of_the_stats_json(models, cli, tmp_path):
    options = {"integrator": "vie", "accuracy": 1e-3}
    stats_file = tmp_path / "stats.json"
    cli("run", models / "chain10.yaml", "--t-final", "0.2", "--sample-period", "0", "-q",
        "--accuracy", "1e-3", "--integrator", "vie", "--stats", stats_file)
    expected = json.loads(stats_file.read_text())["statistics"]

    sim = stiffsim.Simulator(stiffsim.load_scene(models / "chain10.yaml"), **options)
    sim.advance_to(0.2)
    stats = sim.stats
    assert list(stats) == list(expected)
    counters = [k for k in expected if not k.endswith("_seconds")]
    assert {k: stats[k] for k in counters} == {k: expected[k] for k in counters}
    assert stats["steps_taken"] > 0


def test_run_writes_what_the_cli_writes(models, cli, tmp_path):
    args = ["--t-final", "0.05", "--set", "rope.nodes=20", "--integrator", "vie"]
    cli("run", models / "rope.yaml", *args, "-q", "--output", tmp_path / "cli.csv",
        "--stats", tmp_path / "cli.json")
    document = stiffsim.run(models / "rope.yaml", output=tmp_path / "py.csv",
                            stats=tmp_path / "py.json", overrides=ROPE_SMALL, t_final=0.05,
                            integrator="vie")
    assert (tmp_path / "py.csv").read_bytes() == (tmp_path / "cli.csv").read_bytes()
    from_file = json.loads((tmp_path / "py.json").read_text())
    cli_file = json.loads((tmp_path / "cli.json").read_text())
    assert document["samples"] == from_file["samples"] == cli_file["samples"] == 6
    assert document["statistics"]["steps_taken"] == cli_file["statistics"]["steps_taken"]
    assert document["energy"] == cli_file["energy"]


def test_scene_errors_are_input_errors_with_the_cli_message(cli, tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("gravity: [0, 0, -9.81]\ncomponents:\n  - name: rope\n    type: rope\n"
                   "    nodes: 10\n    lenght: 1.0\n")
    with pytest.raises(stiffsim.InputError) as error:
        stiffsim.load_scene(bad)
    assert isinstance(error.value, ValueError)
    assert "bad.yaml:6:5:" in str(error.value)  # file, line, column
    assert "unknown key 'lenght'" in str(error.value)
    result = cli("run", bad, check=False)
    assert result.returncode == 2
    assert cli_error(result) == str(error.value)

    with pytest.raises(stiffsim.InputError, match="cannot open|No such file|not found"):
        stiffsim.load_scene(tmp_path / "missing.yaml")


def test_option_errors_are_input_errors(models):
    scene = stiffsim.load_scene(models / "rope.yaml", ROPE_SMALL)
    with pytest.raises(stiffsim.InputError, match="unknown integrator 'nope'"):
        stiffsim.Simulator(scene, integrator="nope")
    with pytest.raises(stiffsim.InputError, match="step: expected a positive number, got -1"):
        stiffsim.Simulator(scene, step=-1)
    with pytest.raises(stiffsim.InputError, match=r"accuracy: expected a number in \(0, 1\]"):
        stiffsim.Simulator(scene, accuracy=2)
    with pytest.raises(stiffsim.InputError, match="unknown Jacobian scheme"):
        stiffsim.Simulator(scene, jacobian="symbolic")
    with pytest.raises(TypeError, match="unknown option"):
        stiffsim.Simulator(scene, stepsize=1e-3)
    with pytest.raises(stiffsim.InputError, match="cannot create"):
        stiffsim.run(models / "rope.yaml", output="/nonexistent/dir/x.csv", overrides=ROPE_SMALL)


def test_preconditioner_precision_is_an_option(models):
    # The 32x32 cloth's Krylov path applies its supernodal factor in single
    # precision unless asked for double, as --preconditioner-precision does.
    scene = stiffsim.load_scene(models / "cloth.yaml")
    counts = {}
    for precision in ("single", "double"):
        sim = stiffsim.Simulator(scene, newton_solve="krylov", t_final=0.1, fixed_step=True,
                                 preconditioner_precision=precision)
        sim.advance_to()
        # GMRES solves that started from a chord test's solve saved one each.
        solves = (sim.stats["krylov_iterations"] + sim.stats["chord_solves"]
                  - sim.stats["krylov_chord_starts"])
        counts[precision] = (solves, sim.stats["single_precision_solves"])
    assert counts["single"][0] > 0 and counts["single"][1] == counts["single"][0]
    assert counts["double"][0] > 0 and counts["double"][1] == 0
    with pytest.raises(stiffsim.InputError, match="unknown preconditioner precision 'half'"):
        stiffsim.Simulator(scene, preconditioner_precision="half")


def test_numerical_failure_carries_t_and_h(models, cli, tmp_path):
    # Explicit Euler at 10 ms on the stiff cloth (k = 1e6, 32x32 nodes) is far
    # past its stability limit: the first steps blow up.
    options = ["--integrator", "semi-explicit-euler", "--step", "0.01", "--fixed-step"]
    result = cli("run", models / "cloth_stiff.yaml", *options, "-q", check=False)
    assert result.returncode == 3
    sim = stiffsim.Simulator(stiffsim.load_scene(models / "cloth_stiff.yaml"),
                             integrator="semi-explicit-euler", step=0.01, fixed_step=True)
    with pytest.raises(stiffsim.NumericalFailure) as error:
        sim.advance_to(2.0)
    assert isinstance(error.value, RuntimeError)
    assert error.value.h == 0.01
    assert 0.0 <= error.value.t < 2.0
    assert str(error.value) == cli_error(result)
    with pytest.raises(stiffsim.NumericalFailure):
        stiffsim.run(models / "cloth_stiff.yaml", integrator="semi-explicit-euler", step=0.01,
                     fixed_step=True)


INTERRUPTED = textwrap.dedent("""
    import sys, time, stiffsim
    scene = stiffsim.load_scene(sys.argv[1], overrides={"cloth.nodes": [24, 24]})
    print("started", flush=True)
    start = None
    try:
        if sys.argv[2] == "advance_to":
            sim = stiffsim.Simulator(scene, step=1e-3, fixed_step=True)
            sim.advance_to(1e6)
        else:
            stiffsim.run(sys.argv[1], overrides={"cloth.nodes": [24, 24]}, t_final=1e6,
                         step=1e-3, fixed_step=True)
    except KeyboardInterrupt:
        print("KeyboardInterrupt", flush=True)
""")


@pytest.mark.parametrize("call", ["advance_to", "run"])
def test_ctrl_c_interrupts_a_long_integration(models, call):
    process = subprocess.Popen([sys.executable, "-c", INTERRUPTED, str(models / "cloth.yaml"),
                                call], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                               text=True, env=dict(os.environ))
    assert process.stdout.readline().strip() == "started"
    time.sleep(0.5)  # well into the integration
    sent = time.monotonic()
    process.send_signal(signal.SIGINT)
    out, err = process.communicate(timeout=10)
    latency = time.monotonic() - sent
    assert process.returncode == 0, err
    assert out.strip() == "KeyboardInterrupt"
    assert latency < 2.0


def test_bench_reports_reject_an_unusable_directory(tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("")
    with pytest.raises(stiffsim.InputError):
        stiffsim.bench.stability(out=blocker / "sub", quick=True)


def test_stability_report_table_and_its_claim(tmp_path):
    # The quick preset (about 20 s on 2 cores): the table of stability.csv
    # as dicts, and the report's claim for VIE: stable on every case.
    rows = stiffsim.bench.stability(out=tmp_path, quick=True)
    assert (tmp_path / "stability.csv").exists() and (tmp_path / "stability.md").exists()
    with open(tmp_path / "stability.csv", newline="") as f:
        assert list(rows[0]) == next(csv.reader(f))
    vie = [row for row in rows if row["method"] == "vie"]
    assert len(vie) >= 5
    for row in vie:
        assert row["verdict"] == "stable" and row["pass"] == 1, row
        assert isinstance(row["steps"], int) and row["steps"] > 0
