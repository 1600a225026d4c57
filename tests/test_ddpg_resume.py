"""A rerun of a DDPG/TD3/SAC run resumes it exactly, reuses it when complete, and refuses
another configuration unless told to overwrite (``leoc.sb3.checkpoint``, ``train_ddpg``)."""

from __future__ import annotations

import json

import pytest
import torch
from stable_baselines3.common.callbacks import BaseCallback

from leoc.sb3.checkpoint import CHECKPOINT_FILE
from leoc.sb3.train import train_ddpg

# small networks and budgets: the point is the bookkeeping, not learning
TINY = {
    "total_steps": 300,
    "learning_starts": 50,
    "eval_interval": 100,
    "eval_episodes": 1,
    "actor_hidden": (16, 16),
    "critic_hidden": (16, 16),
    "checkpoint_interval": 100,
    "progress": False,
}
STOP_AT = 250  # between the checkpoints at 200 and 300


class StopAt(BaseCallback):
    """Interrupts training (as Ctrl-C does) once ``steps`` environment steps are done."""

    def __init__(self, steps: int) -> None:
        super().__init__()
        self.steps = steps

    def _on_step(self) -> bool:
        if self.num_timesteps == self.steps:
            raise KeyboardInterrupt
        return True


def _parameters(result) -> torch.Tensor:
    return torch.nn.utils.parameters_to_vector(result.model.policy.parameters()).detach()


@pytest.mark.slow
@pytest.mark.parametrize(
    ("algo", "system", "settings"),
    [
        # the authors' noise, reset at episode ends: SB3 resets it when learn starts again,
        # so the checkpoint's copy must be restored after
        ("ddpg", "cartpole", {"noise_reset": True}),
        ("td3", "pendulum", {}),
        ("sac", "mountaincar", {}),
    ],
)
def test_an_interrupted_run_resumes_to_the_uninterrupted_result(
    tmp_path, algo, system, settings
) -> None:
    """Interrupted at step 250 (last checkpoint at 200) and rerun, the run ends with the same
    weights and the same learning curve as the run that was never interrupted, to the last bit;
    the checkpoint is removed once the run is complete."""
    tiny = {**TINY, **settings}
    whole = train_ddpg(system, algo=algo, hybrid=True, seed=3, run_dir=tmp_path / "whole", **tiny)
    cut = tmp_path / "cut"
    with pytest.raises(KeyboardInterrupt):
        train_ddpg(
            system, algo=algo, hybrid=True, seed=3, run_dir=cut, callbacks=[StopAt(STOP_AT)], **tiny
        )
    assert (cut / CHECKPOINT_FILE).is_file() and not (cut / "model.zip").exists()
    resumed = train_ddpg(system, algo=algo, hybrid=True, seed=3, run_dir=cut, **tiny)
    assert torch.equal(_parameters(whole), _parameters(resumed))
    assert resumed.curve == whole.curve
    assert [row["steps"] for row in resumed.curve] == [0, 100, 200, 300]
    assert not (cut / CHECKPOINT_FILE).exists()
    assert json.loads((cut / "curve.json").read_text()) == json.loads(
        (tmp_path / "whole" / "curve.json").read_text()
    )


@pytest.mark.slow
def test_a_complete_run_is_reused_and_another_budget_refused(tmp_path, capsys) -> None:
    """Rerunning a finished run trains nothing and returns it; another budget in the same
    folder is refused in one line naming the setting, and replaced only with overwrite."""
    run = tmp_path / "run"
    first = train_ddpg("pendulum", algo="ddpg", seed=1, run_dir=run, **TINY)
    model_bytes = (run / "model.zip").read_bytes()
    again = train_ddpg("pendulum", algo="ddpg", seed=1, run_dir=run, **{**TINY, "progress": True})
    assert "complete: nothing to train" in capsys.readouterr().out
    assert (run / "model.zip").read_bytes() == model_bytes
    assert again.curve == first.curve and torch.equal(_parameters(again), _parameters(first))
    other = {**TINY, "total_steps": 200}
    with pytest.raises(ValueError, match=r"total_steps: 300 there, 200 here.*--overwrite"):
        train_ddpg("pendulum", algo="ddpg", seed=1, run_dir=run, **other)
    assert (run / "model.zip").read_bytes() == model_bytes
    # replacing it, and stopped before the end: nothing of the old run is left to pass for it
    with pytest.raises(KeyboardInterrupt):
        train_ddpg(
            "pendulum", algo="ddpg", seed=1, run_dir=run, overwrite=True, callbacks=[StopAt(150)],
            **other,
        )  # fmt: skip
    assert not (run / "model.zip").exists() and not (run / "curve.json").exists()
    replaced = train_ddpg("pendulum", algo="ddpg", seed=1, run_dir=run, **other)
    assert replaced.curve[-1]["steps"] == 200
    assert json.loads((run / "config.json").read_text())["total_steps"] == 200


@pytest.mark.slow
def test_a_checkpoint_from_before_the_move_to_leoc_sb3_is_set_aside(tmp_path, capsys) -> None:
    """A run interrupted before leoc.ddpg became leoc.sb3 left a checkpoint that names leoc.ddpg's
    classes; the rerun sets it aside in one line naming the cause and trains afresh, to the
    result of a run never interrupted."""
    run = tmp_path / "run"
    with pytest.raises(KeyboardInterrupt):
        train_ddpg("pendulum", algo="td3", seed=2, run_dir=run, callbacks=[StopAt(150)], **TINY)
    (run / CHECKPOINT_FILE).write_bytes(b"cleoc.ddpg.algorithms\nLeocTD3\n.")  # a pickled class
    capsys.readouterr()
    rerun = train_ddpg("pendulum", algo="td3", seed=2, run_dir=run, **TINY)
    out = capsys.readouterr().out
    assert "checkpoint of an older leoc" in out and "No module named 'leoc.ddpg'" in out
    assert "starting the run afresh" in out
    aside = [path.name.split(".damaged-")[0] for path in run.glob("*.damaged-*")]
    assert aside == [CHECKPOINT_FILE]
    whole = train_ddpg("pendulum", algo="td3", seed=2, run_dir=tmp_path / "whole", **TINY)
    assert rerun.curve == whole.curve and torch.equal(_parameters(rerun), _parameters(whole))
