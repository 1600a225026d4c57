"""PILCO (Deisenroth & Rasmussen, ICML 2011) for the RBF baseline and the LEOC hybrid.

- :mod:`~leoc.pilco.gp`: GP dynamics model (exact, FITC beyond ``max_full_points`` data) and the
  output-pair weights that moment matching contracts with;
- :mod:`~leoc.pilco.moments`: exact moment matching (GP, RBF, linear, sin squash, cos/sin
  augmentation) and Gauss-Hermite quadrature for the hybrid;
- :mod:`leoc.linalg` (one level down, shared): Cholesky with jitter, symmetrising, and the
  blockwise exp-bilinear kernel of the GP second moments;
- :mod:`~leoc.pilco.cost`: saturating cost and its expectation;
- :mod:`~leoc.pilco.propagate`: long-term prediction over the horizon;
- :mod:`~leoc.pilco.rollout`: real rollouts and the hold test;
- :mod:`~leoc.pilco.config`: the validated settings, per-system defaults and the authors'
  (nrjc/LEOC) settings, :func:`authors_pilco_overrides`;
- :mod:`~leoc.pilco.policy`: the RBF baseline and the hybrid, built from the initial data;
- :mod:`~leoc.pilco.objective`: the predicted horizon cost and its L-BFGS minimisation;
- :mod:`~leoc.pilco.checkpoint`: resumable checkpoint, saved controller and trained run
  (:func:`load_pilco_run`);
- :mod:`~leoc.pilco.train`: the training loop only.
"""

from leoc.pilco.checkpoint import PilcoRun, load_pilco_controller, load_pilco_run
from leoc.pilco.config import PilcoConfig, authors_pilco_overrides
from leoc.pilco.cost import expected_saturating_cost, saturating_cost
from leoc.pilco.diagnose import DIAGNOSES, Diagnosis, diagnose_curve, diagnose_run
from leoc.pilco.gp import CholeskyError, GPPosterior, GPSettings, fit_gp, gp_predict
from leoc.pilco.moments import (
    MomentMatch,
    gp_moments,
    linear_moments,
    observation_moments,
    quadrature_moments,
    rbf_moments,
    sin_squash_moments,
)
from leoc.pilco.propagate import SaturatedPolicy, action_moments, predict
from leoc.pilco.train import PilcoResult, train_pilco

__all__ = [
    "DIAGNOSES",
    "CholeskyError",
    "Diagnosis",
    "GPPosterior",
    "GPSettings",
    "MomentMatch",
    "PilcoConfig",
    "PilcoResult",
    "PilcoRun",
    "SaturatedPolicy",
    "action_moments",
    "authors_pilco_overrides",
    "diagnose_curve",
    "diagnose_run",
    "expected_saturating_cost",
    "fit_gp",
    "gp_moments",
    "gp_predict",
    "linear_moments",
    "load_pilco_controller",
    "load_pilco_run",
    "observation_moments",
    "predict",
    "quadrature_moments",
    "rbf_moments",
    "saturating_cost",
    "sin_squash_moments",
    "train_pilco",
]
