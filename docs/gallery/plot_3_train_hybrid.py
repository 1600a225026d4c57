"""
Train a small hybrid and compare it with its LQR
================================================

Train a TD3 hybrid on the pendulum for 600 environment steps with small networks (the paper's
budget is 10k steps with 400-300 networks; see the user guide's DDPG page for what that learns),
then compare it with the LQR it is built on, in the two regimes that matter:

* **at the operating point**, under the impulse test: the hybrid's identities
  :math:`\\pi(a) = G(a)`, :math:`\\partial\\pi/\\partial x(a) = W` make it respond like its LQR
  to first order; how close the responses stay depends on how far the impulse takes the state
  from where :math:`r(x) \\approx 1`, since the paper's relevance lets :math:`H` in everywhere
  else (the ROA relevance of the user guide removes this difference);
* **from the hanging start**, where the LQR alone is helpless (its action saturates and the
  pendulum never comes up) and the hybrid's learned part :math:`H` governs (:math:`r(x)` near 0).

With this tiny budget :math:`H` has not learnt the swing-up; the figure shows where each part of
the hybrid acts, not a trained controller.
"""

import tempfile

import matplotlib.pyplot as plt
import numpy as np

from leoc.control import design_lqr
from leoc.evaluation.robustness import relevance_trace
from leoc.evaluation.rollout import response_test
from leoc.policies import LinearController
from leoc.sb3 import load_ddpg_controller, train_ddpg
from leoc.systems import make_system
from leoc.systems.rollout import rollout

run_dir = tempfile.mkdtemp(prefix="td3_hybrid_")
result = train_ddpg(
    "pendulum",
    "td3",
    hybrid=True,
    seed=0,
    total_steps=600,
    run_dir=run_dir,
    progress=False,
    learning_starts=200,
    eval_interval=300,
    eval_episodes=1,
    actor_hidden=(64, 64),
    critic_hidden=(64, 64),
)
print(f"final evaluation return {result.final_return:.1f} (hybrids that swing up: about -350)")

system = make_system("pendulum")
design = design_lqr(system)
controllers = {
    "LQR": LinearController(design.W, design.b),
    "TD3 hybrid": load_ddpg_controller(run_dir),
}

# %%
# At the operating point: the impulse responses and their metrics.
responses = {
    label: response_test(system, policy, "impulse") for label, policy in controllers.items()
}
for label, response in responses.items():
    metrics = response.metrics
    print(
        f"{label:>10}: peak {np.max(np.abs(response.deviation)):.3f} deg, "
        f"steady-state error {metrics.steady_state_error:.2e} deg, "
        f"settling {metrics.settling_time} steps"
    )

# %%
# From the hanging start: the angle under each controller, and the hybrid's relevance r(x).
start = system.sample_start(np.random.default_rng(0), "swing_up")
fig, (top, middle, bottom) = plt.subplots(3, 1, figsize=(7, 7.5), sharex=False)
for (label, response), style in zip(responses.items(), ("-", "--"), strict=True):
    time = np.arange(response.deviation.size) * system.dt
    top.plot(time, response.deviation, style, label=label)
top.set_title("impulse at the operating point")
top.set_ylabel("theta [deg]")
top.legend()
for (label, policy), style in zip(controllers.items(), ("-", "--"), strict=True):
    trajectory = rollout(system, policy, start)
    time = np.arange(trajectory.states.shape[0]) * system.dt
    middle.plot(time, system.main_coordinate(trajectory.states), style, label=label)
middle.set_title("from the hanging start")
middle.set_ylabel("theta [deg]")
middle.legend()
trace = relevance_trace(system, controllers["TD3 hybrid"], seed=0)
bottom.plot(trace.time, trace.relevance, color="tab:green")
bottom.set_ylim(-0.05, 1.05)
bottom.set_ylabel("r(x) of the hybrid")
bottom.set_xlabel("time [s]")
fig.tight_layout()
