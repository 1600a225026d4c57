"""Stable-Baselines3's DDPG with the LEOC hybrid.

Adapts ``stable_baselines3.DDPG``: :class:`LeocDDPG` is SB3's DDPG with the paper's settings
(``actor_learning_rate``, ``target_update_interval``, ``warmup``, ``critic_loss``,
``target_action_clip``; :mod:`leoc.sb3.common`). SB3's DDPG is its TD3 with one critic, no
policy delay and no target smoothing, and uses TD3's policy classes: the hybrid policy is
:class:`~leoc.sb3.td3.HybridTD3Policy`, also named :data:`HybridDDPGPolicy` here.

References
----------
T. P. Lillicrap et al., "Continuous control with deep reinforcement learning", ICLR 2016.
Y. Zhang and F. Capel, "LEOC: A Principled Method in Integrating Reinforcement Learning and
Classical Control Theory", L4DC 2021, appendix C.
"""

from __future__ import annotations

from stable_baselines3 import DDPG

from leoc.sb3.common import _PaperSettingsMixin
from leoc.sb3.td3 import HybridTD3Policy

__all__ = ["HybridDDPGPolicy", "LeocDDPG"]


class LeocDDPG(_PaperSettingsMixin, DDPG):
    """SB3 ``DDPG`` plus ``actor_learning_rate``, ``target_update_interval``, ``warmup`` and
    ``critic_loss`` (:mod:`leoc.sb3.common`)."""


HybridDDPGPolicy = HybridTD3Policy
"""SB3's DDPG uses TD3's policy classes (with one critic); the hybrid policy is shared too."""
