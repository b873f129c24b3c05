"""stiffsim from Python: load a scene, step it, read its state as NumPy arrays.

    import stiffsim
    scene = stiffsim.load_scene("models/rope.yaml", overrides={"rope.nodes": 20})
    sim = stiffsim.Simulator(scene, integrator="vie", step=1e-3, fixed_step=True)
    sim.advance_to(0.5)
    sim.q, sim.v, sim.stats["steps_taken"]

Everything runs in the compiled library (stiffsim._stiffsim) that the CLI
uses; this file only turns keywords into the CLI's options.

State arrays: sim.q, sim.v and sim.z return copies (a new NumPy array on each
read; writing into it changes nothing). Assigning sim.q = ..., sim.v = ...,
sim.z = ... or sim.t = ... sets the state and restarts the integrator there:
its history (step-size control, dense output) and its statistics start anew.

Errors: bad input (scene files, overrides, options) raises stiffsim.InputError,
a ValueError, with the CLI's message (file, line and key where known); an
integration that cannot continue raises stiffsim.NumericalFailure, a
RuntimeError with the time .t and step .h of the failure. Ctrl-C during
advance_to() or run() raises KeyboardInterrupt after the step in progress.

Threads: integration releases the GIL, but a scene keeps scratch buffers, so
step the simulators of one scene from one thread at a time.
"""

import json as _json

from . import _stiffsim
from ._stiffsim import InputError, NumericalFailure, Scene, integrator_names, set_blas_threads

__all__ = [
    "InputError",
    "NumericalFailure",
    "Scene",
    "Simulator",
    "bench",
    "integrator_names",
    "load_scene",
    "run",
    "set_blas_threads",
]

# The run options of `stiffsim run`, by their CLI names without dashes.
_OPTION_NAMES = (
    "integrator",
    "t_final",
    "step",
    "accuracy",
    "sample_period",
    "fixed_step",
    "error_estimate",
    "jacobian",
    "linear_solver",
    "newton_form",
    "error_estimator",
    "newton_solve",
    "newton_tolerance",
    "preconditioner_precision",
    "full_newton",
    "no_reuse",
)


def _set_arguments(overrides):
    """{"cloth.nodes": [16, 16]} -> ["cloth.nodes=[16, 16]"], as --set takes them.

    A string value is passed as YAML text unchanged; anything else is written
    as JSON, which YAML reads as the same value.
    """
    if overrides is None:
        return []
    if not isinstance(overrides, dict):
        raise InputError("overrides: expected a dict of PATH: VALUE, got %r" % (overrides,))
    sets = []
    for path, value in overrides.items():
        text = value if isinstance(value, str) else _json.dumps(value)
        sets.append("%s=%s" % (path, text))
    return sets


def _run_overrides(options):
    unknown = sorted(set(options) - set(_OPTION_NAMES))
    if unknown:
        raise TypeError(
            "unknown option(s) %s (expected some of: %s)" % (", ".join(unknown), ", ".join(_OPTION_NAMES))
        )
    overrides = _stiffsim._RunOverrides()
    for name, value in options.items():
        if value is None:
            continue
        if name in ("full_newton", "no_reuse", "fixed_step", "error_estimate"):
            value = bool(value)
        elif name in ("t_final", "step", "accuracy", "sample_period"):
            value = float(value)
        setattr(overrides, name, value)
    return overrides


def load_scene(path, overrides=None):
    """Loads a scene file (YAML or bare URDF) after applying `overrides`.

    overrides: {PATH: VALUE} with the keys of the CLI's --set PATH=VALUE
    ("gravity", "simulation.accuracy", "cloth.stretch.k", "cloth.nodes", ...).
    """
    return _stiffsim._load_scene(str(path), _set_arguments(overrides))


class Simulator:
    """An integrator on a scene, from the scene's initial state.

    Keywords are the options of `stiffsim run` without dashes (integrator,
    step, accuracy, fixed_step, error_estimate, t_final, sample_period,
    jacobian, linear_solver, newton_form, error_estimator, newton_solve,
    newton_tolerance, preconditioner_precision, full_newton, no_reuse); each overrides the scene's simulation block
    when given. See the module docstring for the copy rule of q, v and z.
    """

    def __init__(self, scene, **options):
        if isinstance(scene, str):
            raise TypeError("Simulator takes a Scene: use stiffsim.load_scene(%r)" % scene)
        self._sim = _stiffsim._Simulator(scene, _run_overrides(options))

    def step(self, t_limit=float("inf")):
        """Takes one step (fixed or error-controlled) ending no later than t_limit; returns t."""
        return self._sim.step(t_limit)

    def advance_to(self, t=None):
        """Steps until t (default: the scene's t_final) is reached exactly; returns t."""
        return self._sim.advance_to(self._sim.t_final if t is None else t)

    t = property(lambda self: self._sim.t, lambda self, value: setattr(self._sim, "t", value),
                 doc="Time, s. Setting it restarts the integrator.")
    q = property(lambda self: self._sim.q, lambda self, value: setattr(self._sim, "q", value),
                 doc="Positions (a copy). Setting them restarts the integrator.")
    v = property(lambda self: self._sim.v, lambda self, value: setattr(self._sim, "v", value),
                 doc="Velocities (a copy). Setting them restarts the integrator.")
    z = property(lambda self: self._sim.z, lambda self, value: setattr(self._sim, "z", value),
                 doc="Miscellaneous states (a copy). Setting them restarts the integrator.")
    x = property(lambda self: self._sim.x, doc="The whole state [q; v; z] (a copy), as a CSV row.")
    stats = property(lambda self: self._sim.stats,
                     doc="The integrator's statistics since the last restart, named as in --stats.")
    energy = property(lambda self: self._sim.energy, doc="The scene's energy at the state, J.")
    scene = property(lambda self: self._sim.scene)
    integrator = property(lambda self: self._sim.integrator)
    t_final = property(lambda self: self._sim.t_final)
    step_size = property(lambda self: self._sim.step_size, doc="Maximum (or fixed) step, s.")
    accuracy = property(lambda self: self._sim.accuracy)
    fixed_step = property(lambda self: self._sim.fixed_step)

    def __repr__(self):
        return "<stiffsim.Simulator %s on %r at t=%g>" % (self.integrator, self.scene, self.t)


def run(path, output=None, stats=None, vtk=None, overrides=None, **options):
    """Runs a scene as `stiffsim run` does and returns its stats document as a dict.

    output, stats, vtk: the files of -o/--output, --stats and --vtk (None:
    not written). overrides: as load_scene's. Other keywords: the run options
    of Simulator. On a numerical failure the files keep what was computed,
    marked as stopped early, and NumericalFailure is raised.
    """
    request = _stiffsim._RunRequest()
    request.scene = str(path)
    request.sets = _set_arguments(overrides)
    request.overrides = _run_overrides(options)
    request.output = "" if output is None else str(output)
    request.stats = "" if stats is None else str(stats)
    request.vtk = "" if vtk is None else str(vtk)
    return _stiffsim._run(request)


from . import bench  # noqa: E402  (bench uses the names above)
