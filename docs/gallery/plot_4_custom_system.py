"""
A custom system end to end
==========================

The worked example of the user guide's "Bring your own system" page,
``docs/examples/damped_cart.py``: a cart on a rail with a damper and an unstable spring,
written in one file against the :class:`leoc.systems.System` protocol, registered, given its
LQR, and a TD3 hybrid trained on it for a few hundred steps. The hybrid equals its LQR at the
operating point, so the two impulse responses coincide however little it has learnt.
"""

import tempfile

import damped_cart  # docs/examples/damped_cart.py (conf.py puts docs/examples on sys.path)
import matplotlib.pyplot as plt
import numpy as np

from leoc.control import design_lqr
from leoc.evaluation.rollout import response_test
from leoc.policies import LinearController
from leoc.sb3 import load_ddpg_controller
from leoc.systems import make_system

run_dir = tempfile.mkdtemp(prefix="damped_cart_")
peaks = damped_cart.main(steps=300, run_dir=run_dir)  # registers, designs, trains, compares

# %%
# The two impulse responses side by side.
system = make_system("damped_cart")
design = design_lqr(system)
controllers = {
    "lqr": LinearController(design.W, design.b),
    "hybrid": load_ddpg_controller(run_dir),
}
fig, axis = plt.subplots(figsize=(6, 3.2))
for (label, controller), style in zip(controllers.items(), ("-", "--"), strict=True):
    result = response_test(system, controller, "impulse")
    time = np.arange(result.deviation.size) * system.dt
    axis.plot(time, result.deviation, style, label=f"{label} (peak {peaks[label]:.4f} m)")
axis.set_xlabel("time [s]")
axis.set_ylabel("x [m]")
axis.legend()
fig.tight_layout()
