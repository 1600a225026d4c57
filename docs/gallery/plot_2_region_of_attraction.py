"""
Certify and plot a region of attraction
=======================================

:func:`leoc.control.certify_lqr` finds the largest sublevel set :math:`\\{V \\le \\rho\\}` of the
LQR's Lyapunov function :math:`V(x) = z^\\top P z` on which :math:`V` decreases along the
*nonlinear, saturated* closed loop. The level is *proved* by interval arithmetic on boxes
(``certificate.rho``); a sampling estimate with a stated confidence stands beside it
(``certificate.sampled_rho``; the user guide's region-of-attraction page says what each
means). We then simulate a grid of starts and draw which of them the LQR brings to the top and
holds: the empirical basin, which must contain the proved ellipse.

The sample count here is ten times smaller than the default, to keep the build short.
"""

import numpy as np

from leoc.control import certify_lqr, design_lqr
from leoc.evaluation.basins import empirical_basin, slice_grid
from leoc.evaluation.plots.basins import draw_basin_slices
from leoc.policies import LinearController
from leoc.systems import make_system

system = make_system("pendulum")
design = design_lqr(system)
certificate = certify_lqr(system, design, samples=10_000, seed=0)
print(f"proved: rho = {certificate.rho:.4g} ({certificate.basis})")
print(f"extent per state of the proved set = {np.round(certificate.extent, 3)}")
print(
    f"sampled estimate: rho = {certificate.sampled_rho:.4g}; {certificate.samples} samples per "
    f"round, {certificate.rounds} rounds: with confidence {certificate.confidence}, the "
    "violating volume fraction is below "
    f"{certificate.violation_bound:.2g} (a statistical statement, not a proof)"
)

# %%
# The empirical basin on the (theta, theta_dot) slice, and the proved set over it. The grid
# covers the set's extent (10 % beyond it), so that every part of the ellipse has starts.
points = 41
box = 1.1 * certificate.extent
starts = slice_grid(system, (0, 1), box=box, points=points)
basin = empirical_basin(system, LinearController(design.W, design.b), starts)
print(f"LQR brings {basin.fraction:.0%} of the slice's starts to the top and holds")
fig = draw_basin_slices(system, certificate, {"LQR": basin}, (0, 1), points, box)
