"""
LQR and its impulse response on the pendulum
============================================

Linearise the pendulum's discrete step map about the upright position, design the discrete LQR
on it, look at its gains and margins, and run the two response tests the report uses: an
impulse (-1 added to the first action) and a step (-0.2 added to every action), both started at
the operating point.
"""

import matplotlib.pyplot as plt
import numpy as np

from leoc.control import design_lqr
from leoc.evaluation.rollout import response_test
from leoc.policies import LinearController
from leoc.systems import make_system

system = make_system("pendulum")
design = design_lqr(system)  # discrete LQR on the autodiff linearisation of the step map
print("A_d =", np.round(design.A_d, 4).tolist())
print("B_d =", np.round(design.B_d, 4).tolist())
print("K   =", np.round(design.K, 3).tolist(), " spectral radius", round(design.spectral_radius, 4))
print("W   =", np.round(design.W, 3).tolist(), "(acts on the observation [cos, sin, theta_dot])")
print(design.margins)

# %%
# The controller is :math:`G(o) = W o + b` on the observation; ``b`` makes :math:`G(a) = u_{eq}`.
linear = LinearController(design.W, design.b)
results = {test: response_test(system, linear, test) for test in ("impulse", "step")}
for test, result in results.items():
    print(test, result.metrics)

# %%
# Both responses, the main coordinate's deviation in degrees against time.
fig, axes = plt.subplots(1, 2, figsize=(9, 3.2), sharex=True)
for axis, (test, result) in zip(axes, results.items(), strict=True):
    time = np.arange(result.deviation.size) * system.dt
    axis.plot(time, result.deviation, color="tab:blue")
    axis.axhline(0.0, color="grey", lw=0.8)
    axis.set_title(f"{test}: settles in {result.metrics.settling_time} steps")
    axis.set_xlabel("time [s]")
axes[0].set_ylabel("theta [deg]")
fig.tight_layout()
