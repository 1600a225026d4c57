"""
Deploy a trained controller: leoc.load in a gymnasium loop, then ONNX
=====================================================================

Train a tiny DDPG hybrid (the smoke profile: a few hundred steps, so a pipeline check, not a
good controller), load it with ``leoc.load`` (:func:`leoc.deploy.load`) and run it in a plain
gymnasium loop on leoc's pendulum, deciding once per control period and holding the action in
between. Then export the same decision to ONNX, check it, and run the exported model with ONNX
Runtime alone in the same loop: the two records are the same.
"""

import tempfile
from pathlib import Path

import gymnasium
import matplotlib.pyplot as plt
import numpy as np

import leoc
from leoc.cli import main
from leoc.deploy import export_controller

folder = Path(tempfile.mkdtemp())
run = folder / "ddpg_hybrid"
main(
    ["train", "pendulum", "--algo", "ddpg", "--hybrid", "--profile", "smoke", "--quiet"]
    + ["--out", str(run)]
)
controller = leoc.load(run)
print(controller)
print("control period:", controller.period_steps, "step(s) =", controller.period, "s")
print("LQR gain W on [cos, sin, theta_dot]:", np.round(controller.design.W, 3).tolist())
print("hybrid spec:", controller.hybrid_spec)

# %%
# A plain gymnasium loop: one decision per control period, the action held in between. The env
# starts 0.4 rad from upright (``options`` of leoc's envs), where the relevance is below 1 and
# the learned part shares the decision.


def run_episode(decide, steps=100):
    """theta (rad) along one episode of leoc's pendulum env under ``decide(obs) -> action``."""
    env = gymnasium.make("leoc/PendulumSwingUp-v0")
    obs, info = env.reset(seed=0, options={"start": "operating_point", "offset": [0.4, 0.0]})
    thetas = [info["state"][0]]
    for step in range(steps):
        if step % controller.period_steps == 0:
            action = decide(obs)
        obs, reward, terminated, truncated, info = env.step(action)
        thetas.append(info["state"][0])
        if terminated or truncated:
            break
    env.close()
    return np.array(thetas)


with_leoc = run_episode(controller.act)

# %%
# Export the whole decision (learned part, relevance, LQR, blend, clip) as one float64 ONNX
# model; the export is checked against torch before it is written, and the control period,
# layouts, units, limits and LQR design go to ``controller.onnx.json`` beside it.
result = export_controller(controller, folder / "controller.onnx", "onnx", count=10_000)
print(result.check.describe("ONNX Runtime"))

import onnxruntime  # noqa: E402 - what a deployment target needs: onnxruntime and numpy

session = onnxruntime.InferenceSession(str(result.model), providers=["CPUExecutionProvider"])
with_onnx = run_episode(lambda obs: session.run(["action"], {"observation": obs[None]})[0][0])
print(
    "largest difference of theta, leoc.load vs ONNX Runtime:", np.abs(with_leoc - with_onnx).max()
)

# %%
# The two closed loops, theta in degrees against time.
time = np.arange(with_leoc.size) * controller.system.dt
fig, axis = plt.subplots(figsize=(6, 3))
axis.plot(time, np.degrees(with_leoc), label="leoc.load(run).act", lw=3, alpha=0.5)
axis.plot(time, np.degrees(with_onnx), "--", label="ONNX Runtime", color="k")
axis.axhline(0.0, color="grey", lw=0.8)
axis.set_xlabel("time [s]")
axis.set_ylabel("theta [deg]")
axis.legend()
fig.tight_layout()
