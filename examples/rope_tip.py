"""Tip height of the hanging rope (models/rope.yaml) with vie and rk45.

    PYTHONPATH=build/python /usr/bin/python3 examples/rope_tip.py [out.png]

Loads the scene once, runs it with the velocity-implicit Euler integrator
and with the explicit Dormand-Prince pair at the scene's accuracy, samples
the free end's height every 10 ms and plots both against time (Agg backend:
no display needed). Prints the steps and wall time each method took.
"""

import os
import sys
import time

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import stiffsim  # noqa: E402

here = os.path.dirname(os.path.abspath(__file__))
out = sys.argv[1] if len(sys.argv) > 1 else os.path.join(here, "rope_tip.png")
scene = stiffsim.load_scene(os.path.join(here, "..", "models", "rope.yaml"))
tip = scene.position_names.index("rope/n49/z")  # the free end (node 0 is pinned)
times = np.arange(0.0, scene.t_final + 1e-9, 0.01)

fig, ax = plt.subplots(figsize=(6, 3.2), dpi=80)
for method, style in (("vie", "-"), ("rk45", "--")):
    sim = stiffsim.Simulator(scene, integrator=method)
    start = time.perf_counter()
    heights = []
    for t in times:
        sim.advance_to(t)
        heights.append(sim.q[tip])
    seconds = time.perf_counter() - start
    steps = sim.stats["steps_taken"]
    print("%-5s %6d steps  %7.3f s  tip at t = %g: z = %.4f m" % (method, steps, seconds,
                                                                  sim.t, heights[-1]))
    ax.plot(times, heights, style, label="%s (%d steps)" % (method, steps))
ax.set_xlabel("t (s)")
ax.set_ylabel("tip height z (m)")
ax.set_title("%s: %d free nodes, accuracy %g" % (scene.name, scene.dofs["nq"] // 3,
                                                   scene.accuracy))
ax.legend()
fig.tight_layout()
fig.savefig(out)
print("wrote", out)
