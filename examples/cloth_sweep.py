"""Time per step of the cloth (models/cloth.yaml) against its size.

    PYTHONPATH=build/python /usr/bin/python3 examples/cloth_sweep.py

Runs vie at a fixed step of 1/60 s for 0.5 s on n x n cloths and prints the
wall time per step, with the Newton work that explains it.
"""

import os
import time

import stiffsim

here = os.path.dirname(os.path.abspath(__file__))
path = os.path.join(here, "..", "models", "cloth.yaml")
print("%6s %6s %6s %12s %10s %15s" % ("nodes", "DOFs", "steps", "ms/step", "Newton it.",
                                     "factorizations"))
for n in (8, 16, 24, 32):
    scene = stiffsim.load_scene(path, overrides={"cloth.nodes": [n, n]})
    sim = stiffsim.Simulator(scene, integrator="vie", step=1 / 60, fixed_step=True)
    start = time.perf_counter()
    sim.advance_to(0.5)
    seconds = time.perf_counter() - start
    stats = sim.stats
    print("%6s %6d %6d %12.3f %10d %15d" % ("%dx%d" % (n, n), scene.dofs["nv"], stats["steps_taken"],
                                            1e3 * seconds / stats["steps_taken"],
                                            stats["newton_raphson_iterations"],
                                            stats["iteration_matrix_factorizations"]))
