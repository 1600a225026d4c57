"""Policies: linear controller, RBF network, MLP actor, the LEOC hybrid and output saturation.

Plain torch modules (float64 by default) mapping observations (..., D) to actions (..., F).
:class:`HybridPolicy` blends a :class:`LinearController` G with any nonlinear module H,
pi(x) = sat(r(x) G(x) + (1 - r(x)) H(x)), so that pi(a) = G(a) and dpi/dx(a) = W at the
operating point a (Zhang & Capel, L4DC 2021).
"""

from .held import HeldPolicy, lqr_controller, with_control_period
from .hybrid import SMOOTH_SATURATION_ATOL, HybridOutput, HybridPolicy
from .linear import LinearController
from .mlp import DEFAULT_HIDDEN_SIZES, MLPActor
from .rbf import RBFNetwork
from .relevance import (
    DEFAULT_ROA_WIDTH,
    RELEVANCE_KINDS,
    RELEVANCE_PARAMETRISATIONS,
    FlooredRelevance,
    LyapunovRelevance,
    ObservationDeviation,
    PaperRelevance,
    PrecisionRelevance,
    ROARelevance,
    paper_relevance,
    relevance_floor,
    relevance_of_distance,
)
from .saturation import SATURATION_MODES, saturate
from .spec import (
    RELEVANCE_DESIGNS,
    HybridDesign,
    HybridSpec,
    RelevanceDesign,
    build_hybrid,
    hybrid_design,
    roa_hybrid,
)

__all__ = [
    "DEFAULT_HIDDEN_SIZES",
    "DEFAULT_ROA_WIDTH",
    "RELEVANCE_DESIGNS",
    "RELEVANCE_KINDS",
    "RELEVANCE_PARAMETRISATIONS",
    "SATURATION_MODES",
    "SMOOTH_SATURATION_ATOL",
    "FlooredRelevance",
    "HeldPolicy",
    "HybridDesign",
    "HybridOutput",
    "HybridPolicy",
    "HybridSpec",
    "LinearController",
    "LyapunovRelevance",
    "MLPActor",
    "ObservationDeviation",
    "PaperRelevance",
    "PrecisionRelevance",
    "ROARelevance",
    "RBFNetwork",
    "RelevanceDesign",
    "build_hybrid",
    "hybrid_design",
    "lqr_controller",
    "paper_relevance",
    "relevance_floor",
    "relevance_of_distance",
    "roa_hybrid",
    "saturate",
    "with_control_period",
]
