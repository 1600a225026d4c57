"""
Certify and plot a region of attraction
=======================================

:func:`leoc.control.certify_lqr` finds the largest sublevel set :math:`\\{V \\le \\rho\\}` of the
LQR's Lyapunov function :math:`V(x) = z^\\top P z` on which :math:`V` decreases along the
*nonlinear, saturated* closed loop, by sampling with a stated confidence (the user guide's
region-of-attraction page says what is proved and what is sampled). We then simulate a grid of
starts and draw which of them the LQR brings to the top and holds: the empirical basin, which
must contain the certified ellipse.

The sample count here is ten times smaller than the default, to keep the build short.
"""

import matplotlib.pyplot as plt
import numpy as np

from leoc.control import certify_lqr, design_lqr, empirical_basin, plot_basins, slice_grid
from leoc.policies import LinearController
from leoc.systems import make_system

system = make_system("pendulum")
design = design_lqr(system)
certificate = certify_lqr(system, design, samples=10_000, seed=0)
print(f"rho = {certificate.rho:.4g}, extent per state = {np.round(certificate.extent, 3)}")
print(
    f"{certificate.samples} samples per round, {certificate.rounds} rounds: with confidence "
    f"{certificate.confidence}, the violating volume fraction is below "
    f"{certificate.violation_bound:.2g}"
)

# %%
# The empirical basin on the (theta, theta_dot) slice, and the certified set over it.
points = 41
starts = slice_grid(system, (0, 1), points=points)
basin = empirical_basin(system, LinearController(design.W, design.b), starts)
print(f"LQR brings {basin.fraction:.0%} of the slice's starts to the top and holds")
path = plot_basins(system, certificate, {"LQR": basin}, (0, 1), points, "roa_pendulum.png")

fig, axis = plt.subplots(figsize=(5.5, 5.2))
axis.imshow(plt.imread(path))
axis.set_axis_off()
fig.tight_layout()
