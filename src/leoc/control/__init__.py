"""Linearisation, LQR design, stability margins and the certified region of attraction about
the operating point, of the LQR and of any trained controller (empirical basins:
:mod:`leoc.evaluation.basins`)."""

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
from leoc.control.roa import (
    LevelProof,
    LyapunovCertificate,
    certify_level,
    certify_lqr,
    lqr_closed_loop,
    lyapunov_value,
    state_deviation,
)
from leoc.control.trained import (
    ControllerCertificate,
    Equilibrium,
    certify_controller,
    find_equilibrium,
)

__all__ = [
    "ControllerCertificate",
    "DESIGN_METHODS",
    "Equilibrium",
    "LevelProof",
    "LyapunovCertificate",
    "LQRDesign",
    "Linearisation",
    "StabilityMargins",
    "certify_controller",
    "certify_level",
    "certify_lqr",
    "check_stabilisable",
    "lqr_closed_loop",
    "lyapunov_value",
    "state_deviation",
    "design_lqr",
    "find_equilibrium",
    "linearise",
    "loop_margins",
    "observation_gain",
    "stable_gain_interval",
]
