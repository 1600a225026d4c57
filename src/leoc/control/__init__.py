"""Linearisation, LQR design and stability margins about the operating point."""

from leoc.control.lqr import (
    DESIGN_METHODS,
    Linearisation,
    LQRDesign,
    StabilityMargins,
    check_stabilisable,
    design_lqr,
    linearise,
    loop_margins,
    observation_gain,
    stable_gain_interval,
)

__all__ = [
    "DESIGN_METHODS",
    "LQRDesign",
    "Linearisation",
    "StabilityMargins",
    "check_stabilisable",
    "design_lqr",
    "linearise",
    "loop_margins",
    "observation_gain",
    "stable_gain_interval",
]
