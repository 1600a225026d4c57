r"""A proved region of attraction for any controller: a trained hybrid, a baseline, an LQR.

Letters: S state dimension.

:func:`certify_controller` proves, for the sampled-data closed loop the controller runs
(:math:`F(x) = f^{(k)}(x, \pi(o(x)))`, the action held for its control period :math:`k`), that
a sublevel set of a quadratic :math:`V(x) = (x - x^*)^\top P (x - x^*)` is positively invariant
and attracted to :math:`x^*`:

1. **Its own equilibrium** :math:`x^*` near the operating point :math:`a`
   (:func:`find_equilibrium`): Newton's method on :math:`F(x) - x = 0` from :math:`a`, with the
   autodiff Jacobian and a halving line search. A hybrid's is :math:`a` itself
   (:math:`\pi(a) = G(a)`); a baseline's may be offset, and that offset is its steady-state
   error. An equilibrium is accepted within the operating region
   (``System.operating_region``) and with a residual :math:`|F(x^*) - x^*|` of at most
   :data:`EQUILIBRIUM_TOL` of that region per coordinate; otherwise the proof is centred on
   :math:`a` and can only show practical stability (below).
2. **Two candidate V** (:data:`LYAPUNOV_CHOICES`): the LQR's Riccati matrix :math:`P`
   (``lqr``, when a design is given) and the discrete Lyapunov matrix of the controller's own
   linearisation :math:`J = \partial F / \partial x (x^*)`, :math:`J^\top P J - P = -Q` with
   :math:`Q = \operatorname{diag}(1 / \text{region}_i^2)` (``own``; it exists when the spectral
   radius of :math:`J` is below 1). Each is certified by :func:`leoc.control.certify_level`
   centred on :math:`x^*`: sampled estimate, then the interval proof
   (:func:`leoc.control.proof.prove_level`). The one whose proved ellipsoid has the larger
   volume is kept (``best``); both are reported.
3. **Practical stability.** The asymptotic proof shows :math:`V(F(x)) < V(x)` for
   :math:`\varepsilon^2 < V(x) \le \rho`, with :math:`\varepsilon` set by the residual
   :math:`|F(x^*) - x^*|` (0 for an exact fixed point of the floating-point loop); its inner
   ball maps into itself, so every trajectory from :math:`\{V \le \rho\}` converges to
   :math:`x^*` (or enters :math:`\{V \le \varepsilon^2\}`). Where no such claim can exist (no
   equilibrium near a, or one whose linearisation is unstable: a baseline oscillating about
   its hold point), a proof of practical stability is tried (:data:`PRACTICAL`): the first
   V (the LQR's P when a design is given) and V fitted to sampled decrease about the loop's
   attractor (:mod:`leoc.control.practical`) are sampled, and the one whose sampled target
   has the largest volume is proved: :math:`\{V \le \rho\}` invariant and every
   trajectory from it entering :math:`\{V \le u\}` in finite time and staying there, u the
   ``ultimate_level`` (:func:`leoc.control.certify_level` with ``practical=True``; the
   argument is in :mod:`leoc.control.proof`). ``claim`` says which was proved; every level is
   reported (``rho``, ``excluded_level``, ``ultimate_level``).

The proof needs interval rules for every operation of the controller
(:mod:`leoc.control.intervals`): leoc's MLP actors, RBF networks, every relevance and
saturation, SAC's squashed mean, PILCO's held policies have them; an operation without one is
reported as ``limited_by = "unsupported"``, never guessed.
"""

from __future__ import annotations

import math
import time
from typing import Any, NamedTuple

import numpy as np
import scipy.linalg
import torch

from leoc.control.practical import practical_candidates
from leoc.control.proof import MAX_BOXES, MAX_SECONDS, check_device
from leoc.control.roa import (
    DEFAULT_SAMPLES,
    LyapunovCertificate,
    certify_level,
    held_map,
    state_deviation,
)
from leoc.names import LYAPUNOV_CHOICES
from leoc.systems.base import DTYPE, System
from leoc.systems.rollout import control_period

__all__ = [
    "ControllerCertificate",
    "Equilibrium",
    "best_candidate",
    "certify_controller",
    "find_equilibrium",
]

EQUILIBRIUM_TOL = 1e-9
"""An equilibrium is accepted when ``|F(x) - x|`` is at most this fraction of the operating
region's half-width in every coordinate (Newton reaches about 1e-15 on the paper systems)."""
NEWTON_ITERATIONS = 60
"""Newton steps at most (each with up to ``LINE_SEARCH_HALVINGS`` halvings)."""
LINE_SEARCH_HALVINGS = 30
"""Halvings of a Newton step at most, until the residual shrinks (else the search stops)."""
CONTROLLER_BATCH = 512
"""Boxes per batched call of a controller's proof: a 400x300 actor on interval jets takes
seconds per batch on 2 cores, so the wall-clock budget is checked often (the LQR's own proof
keeps :data:`leoc.control.proof.BATCH`)."""
ACCELERATOR_BATCH = 16_384
"""Boxes per batched call on a GPU: a 400x300 hybrid's enclosures ran at 0.65 million boxes/s
in batches of 16384 on an H200, 0.17 million in batches of 4096 (a search of large batches
also evaluates boxes a smaller one would prune: docs/user_guide/roa.md, "On a GPU")."""
PRACTICAL = "practical"
"""The candidate of :func:`certify_controller`'s practical-stability proof (tried when no
asymptotic claim can exist: no equilibrium, or an unstable one; its V the first candidate's or
one fitted about the attractor, :mod:`leoc.control.practical`)."""
STABLE_RADIUS = 1.0
"""The own-linearisation V needs the spectral radius of J below this."""


class Equilibrium(NamedTuple):
    """A fixed point of the held closed loop near the operating point (:func:`find_equilibrium`).

    Attributes
    ----------
    state : (S,) array
        ``x*`` (the operating point a when none was accepted).
    found : bool
        Whether ``x*`` was accepted (residual within :data:`EQUILIBRIUM_TOL` of the operating
        region, ``x*`` inside it).
    residual : float
        ``max_i |F(x*) - x*|_i / region_i`` (angles wrapped).
    iterations : int
        Newton steps taken.
    jacobian : (S, S) array
        ``dF/dx`` at ``x*``.
    spectral_radius : float
        Of ``jacobian``: below 1, the linearisation at ``x*`` is stable.
    rejected : tuple of float, optional
        Where the Newton search ended when that point was not accepted, as ``x - a`` (angles
        wrapped): a fixed point outside the operating region (its residual
        ``rejected_residual`` within the tolerance), or where the search stalled.
    rejected_residual : float, optional
    """

    state: np.ndarray
    found: bool
    residual: float
    iterations: int
    jacobian: np.ndarray
    spectral_radius: float
    rejected: tuple[float, ...] | None = None
    rejected_residual: float | None = None

    def offset(self, system: System) -> np.ndarray:
        """``x* - a`` (S,), angles wrapped: the steady-state error of the controller."""
        point = torch.as_tensor(self.state, dtype=DTYPE).unsqueeze(0)
        return state_deviation(system, point)[0].numpy()


def _residual(system: System, closed, x: np.ndarray) -> np.ndarray:
    """``F(x) - x`` (S,), angles wrapped."""
    point = torch.as_tensor(x, dtype=DTYPE)
    with torch.no_grad():
        following = closed(point).unsqueeze(0)
    return state_deviation(system, following, x)[0].numpy()


def _scaled_size(system: System, residual: np.ndarray) -> float:
    region = np.asarray(system.operating_region, dtype=float)
    size = np.abs(residual) / region
    return float(np.max(size)) if np.all(np.isfinite(size)) else math.inf


def _newton_step(system: System, closed, x: np.ndarray, residual: np.ndarray) -> np.ndarray:
    """The next iterate: a Newton step on ``F(x) - x``, halved until the residual shrinks."""
    point = torch.as_tensor(x, dtype=DTYPE)
    jacobian = torch.autograd.functional.jacobian(closed, point).numpy()
    step = np.linalg.lstsq(jacobian - np.eye(x.size), -residual, rcond=None)[0]
    size = _scaled_size(system, residual)
    for _ in range(LINE_SEARCH_HALVINGS):
        trial = x + step
        if _scaled_size(system, _residual(system, closed, trial)) < size:
            return trial
        step = 0.5 * step
    return x


def find_equilibrium(
    system: System, controller: Any, action_repeat: int | None = None
) -> Equilibrium:
    """The closed loop's fixed point nearest the operating point, by damped Newton from a
    (module docstring).

    Parameters
    ----------
    system : System
    controller : callable
        Observation (B, O) float64 -> action (B, A).
    action_repeat : int, optional
        Control period (default the controller's ``action_repeat``, else 1).
    """
    repeat = control_period(controller, action_repeat)
    closed = held_map(system, controller, repeat)
    operating = np.asarray(system.operating_state, dtype=float)
    x, iterations = operating.copy(), 0
    residual = _residual(system, closed, x)
    while iterations < NEWTON_ITERATIONS and _scaled_size(system, residual) > 0.0:
        following = _newton_step(system, closed, x, residual)
        if np.array_equal(following, x):
            break
        x, iterations = following, iterations + 1
        residual = _residual(system, closed, x)
    return _equilibrium(system, closed, operating, x, residual, iterations)


def _equilibrium(
    system: System, closed, operating: np.ndarray, x: np.ndarray, residual, iterations: int
) -> Equilibrium:
    """The :class:`Equilibrium` of a Newton search ending at ``x`` (a if not accepted)."""
    size = _scaled_size(system, residual)
    region = np.asarray(system.operating_region, dtype=float)
    offset = state_deviation(system, torch.as_tensor(x, dtype=DTYPE).unsqueeze(0))[0].numpy()
    found = size <= EQUILIBRIUM_TOL and bool(np.all(np.abs(offset) <= region))
    rejected = None if found else (tuple(float(v) for v in offset), size)
    if not found:
        x = operating.copy()
        size = _scaled_size(system, _residual(system, closed, x))
    jacobian = torch.autograd.functional.jacobian(closed, torch.as_tensor(x, dtype=DTYPE))
    jacobian = jacobian.numpy()
    radius = float(np.max(np.abs(np.linalg.eigvals(jacobian))))
    return Equilibrium(x, found, size, iterations, jacobian, radius, *(rejected or (None, None)))


def own_lyapunov_matrix(system: System, equilibrium: Equilibrium) -> np.ndarray | None:
    """``P`` with ``J^T P J - P = -Q``, ``Q = diag(1 / region^2)``, J the loop's Jacobian at
    ``x*``; None when J is not stable (spectral radius >= 1)."""
    if not equilibrium.spectral_radius < STABLE_RADIUS:
        return None
    region = np.asarray(system.operating_region, dtype=float)
    weight = np.diag(1.0 / region**2)
    matrix = scipy.linalg.solve_discrete_lyapunov(equilibrium.jacobian.T, weight)
    return 0.5 * (matrix + matrix.T)


class ControllerCertificate(NamedTuple):
    """A controller's proved region (:func:`certify_controller`).

    Attributes
    ----------
    certificate : LyapunovCertificate
        The chosen V's certificate, centred on ``equilibrium.state`` (``rho`` the proved level,
        ``proof.excluded_level`` the practical-stability level).
    lyapunov : str
        Which V it is: ``lqr`` (the LQR's Riccati P), ``own`` (the discrete Lyapunov matrix
        of the controller's linearisation at its equilibrium), ``region`` (neither exists) or,
        for a practical claim, ``fitted`` about the attractor (``practical_v``; its centre is
        ``certificate.operating_state``).
    equilibrium : Equilibrium
    candidates : dict
        Every V tried: name -> :class:`LyapunovCertificate` (``region``, ``diag(1 /
        region^2)``, only when neither other V exists).
    seconds : float
    practical_v : str, optional
        The V the practical-stability proof kept, in full (``fitted k=... outer=...``; None
        where none was tried).
    """

    certificate: LyapunovCertificate
    lyapunov: str
    equilibrium: Equilibrium
    candidates: dict[str, LyapunovCertificate]
    seconds: float
    practical_v: str | None = None

    @property
    def rho(self) -> float:
        """The proved level (0: nothing proved)."""
        return self.certificate.rho

    @property
    def claim(self) -> str:
        """``asymptotic`` (trajectories converge to ``equilibrium.state``) or ``practical``
        (they enter and stay in ``{V <= certificate.proof.ultimate_level}``)."""
        proof = self.certificate.proof
        return "asymptotic" if proof is None else proof.claim

    @property
    def limited_by(self) -> str:
        """What set ``rho``: the proof's ``limited_by``, or ``no equilibrium``/``unstable
        linearisation`` when no proof could start."""
        proof = self.certificate.proof
        if self.certificate.rho == 0.0 and not self.equilibrium.found:
            return "no equilibrium"
        if self.certificate.sampled_rho == 0.0 and not self.certificate.linear_decrease:
            return "unstable linearisation"
        return "sampled" if proof is None else proof.limited_by

    def summary(self, system: System) -> dict[str, Any]:
        """JSON-friendly description (reproducible: no wall-clock seconds inside)."""
        proof = self.certificate.proof
        return {
            "rho": self.rho,
            "excluded_level": 0.0 if proof is None else proof.excluded_level,
            "claim": self.claim,
            "ultimate_level": 0.0 if proof is None else proof.ultimate_level,
            "lyapunov": self.lyapunov,
            "practical_v": self.practical_v,
            "limited_by": self.limited_by,
            "log_volume": log_volume(self.certificate),
            "equilibrium": self.equilibrium.state.tolist(),
            "equilibrium_found": self.equilibrium.found,
            "equilibrium_residual": self.equilibrium.residual,
            "rejected_offset": _listed(self.equilibrium.rejected),
            "rejected_residual": self.equilibrium.rejected_residual,
            "offset": self.equilibrium.offset(system).tolist(),
            "spectral_radius": self.equilibrium.spectral_radius,
            "certificate": self.certificate.summary(),
            "candidates": {
                name: {
                    "rho": entry.rho,
                    "log_volume": log_volume(entry),
                    "limited_by": "sampled" if entry.proof is None else entry.proof.limited_by,
                }
                for name, entry in self.candidates.items()
            },
        }


def _listed(values: tuple[float, ...] | None) -> list[float] | None:
    return None if values is None else list(values)


def log_volume(certificate: LyapunovCertificate) -> float:
    r"""Log of the proved ellipsoid's volume :math:`\{V \le \rho\}` up to the unit ball's
    constant: :math:`\tfrac{S}{2} \ln \rho - \tfrac12 \ln \det P`; ``-inf`` when rho = 0."""
    if not certificate.rho > 0.0:
        return -math.inf
    _, logdet = np.linalg.slogdet(certificate.P)
    return float(0.5 * certificate.P.shape[0] * math.log(certificate.rho) - 0.5 * logdet)


def _candidate_matrices(
    system: System, equilibrium: Equilibrium, design: Any, lyapunov: str
) -> dict[str, np.ndarray]:
    """The candidate P by name (``lqr`` needs a design; ``own`` a stable linearisation). With
    neither, ``region``: ``diag(1 / region^2)``, which proves nothing past an unstable
    linearisation but states why."""
    if lyapunov not in LYAPUNOV_CHOICES:
        raise ValueError(f"lyapunov: expected one of {LYAPUNOV_CHOICES}, found {lyapunov!r}")
    if lyapunov == "lqr" and design is None:
        raise ValueError("design: expected an LQRDesign with lyapunov='lqr', found None")
    matrices: dict[str, np.ndarray] = {}
    if lyapunov != "own" and design is not None:
        matrices["lqr"] = np.asarray(design.P, dtype=float)
    own = own_lyapunov_matrix(system, equilibrium) if lyapunov != "lqr" else None
    if own is not None:
        matrices["own"] = own
    if not matrices:
        region = np.asarray(system.operating_region, dtype=float)
        matrices["region"] = np.diag(1.0 / region**2)
    return matrices


def best_candidate(candidates: dict[str, LyapunovCertificate]) -> str:
    """The candidate with the largest proved volume (the first on a tie, ``lqr`` before
    ``own``): the V a controller's proof keeps (``best``), and its LQR reference's
    (:func:`leoc.evaluation.proved_regions.lqr_reference`)."""
    names = list(candidates)
    volumes = [log_volume(candidates[name]) for name in names]
    return names[int(np.argmax(volumes))] if max(volumes) > -math.inf else names[0]


def _batch(device: Any) -> int:
    """Boxes per batched call on ``device`` (checked)."""
    return CONTROLLER_BATCH if check_device(device).type == "cpu" else ACCELERATOR_BATCH


def certify_controller(
    system: System,
    controller: Any,
    design: Any = None,
    *,
    action_repeat: int | None = None,
    lyapunov: str = "best",
    samples: int = DEFAULT_SAMPLES,
    seed: int = 0,
    max_boxes: int = MAX_BOXES,
    max_seconds: float = MAX_SECONDS,
    device: Any = "cpu",
) -> ControllerCertificate:
    """Prove a region of attraction of ``controller``'s own closed loop (module docstring).

    Parameters
    ----------
    system : System
        The plant the controller runs on.
    controller : callable
        Observation (B, O) float64 -> action (B, A), runnable on interval jets (leoc's are).
    design : LQRDesign, optional
        Its ``P`` is the ``lqr`` candidate V (left out: only the ``own`` V).
    action_repeat : int, optional
        Control period (default the controller's ``action_repeat``, else 1).
    lyapunov : {"best", "lqr", "own"}
    samples, seed :
        :func:`~leoc.control.certify_level`'s sampled estimate (the proof's target).
    max_boxes, max_seconds, device :
        Box budget of each candidate's proof; wall-clock budget of the box searches, shared
        equally by the candidates; where the boxes are evaluated
        (:func:`~leoc.control.proof.prove_level`; the rest runs on the CPU).
    """
    started = time.perf_counter()
    repeat = control_period(controller, action_repeat)
    options = {"action_repeat": repeat, "samples": samples, "seed": seed}
    options.update(max_boxes=max_boxes, batch=_batch(device), device=device)
    equilibrium = find_equilibrium(system, controller, repeat)
    options["equilibrium"] = equilibrium.state
    matrices = _candidate_matrices(system, equilibrium, design, lyapunov)
    share = max_seconds / len(matrices)
    candidates = {
        name: certify_level(system, matrix, controller, max_seconds=share, **options)
        for name, matrix in matrices.items()
    }
    chosen = best_candidate(candidates)
    certificate = candidates[chosen]
    proposed = None
    if certificate.rho == 0.0 and not _stable_equilibrium(equilibrium):
        left = max(0.0, max_seconds - (time.perf_counter() - started))
        first = next(iter(matrices))
        proposed, practical = _practical(
            system, controller, (first, matrices[first], equilibrium.state), left, options
        )
        candidates[PRACTICAL] = practical
        if practical.rho > 0.0:
            chosen, certificate = proposed.split(" ")[0], practical
    seconds = time.perf_counter() - started
    return ControllerCertificate(certificate, chosen, equilibrium, candidates, seconds, proposed)


def _practical(
    system: System,
    controller: Any,
    first: tuple[str, np.ndarray, np.ndarray],
    max_seconds: float,
    options: dict[str, Any],
) -> tuple[str, LyapunovCertificate]:
    """The practical-stability certificate (module docstring, 3) and its V's name: every
    candidate V (:func:`leoc.control.practical.practical_candidates`) sampled, the one whose
    sampled target has the largest volume proved."""
    proposals = practical_candidates(
        system, controller, options["action_repeat"], first, options["seed"]
    )
    sampled = {
        name: certify_level(
            system, P, controller, practical=True, prove=False, **{**options, "equilibrium": c}
        )
        for name, (P, c) in proposals.items()
    }
    name = best_candidate(sampled)
    P, centre = proposals[name]
    certificate = certify_level(
        system,
        P,
        controller,
        practical=True,
        **{**options, "equilibrium": centre, "max_seconds": max_seconds},
    )
    return name, certificate


def _stable_equilibrium(equilibrium: Equilibrium) -> bool:
    """Whether an asymptotic proof about ``equilibrium`` can exist: one was found and its
    linearisation is stable (else :func:`certify_controller` tries practical stability)."""
    return equilibrium.found and equilibrium.spectral_radius < STABLE_RADIUS
