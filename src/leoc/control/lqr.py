"""Linearisation of the discrete step map and LQR design about the operating point.

The default design is *discrete*: the step map ``x' = f(x, u)`` of the simulator is linearised
by automatic differentiation at the operating point ``(a, u_eq)``,

.. math::

    A_d = \\partial f / \\partial x, \\qquad B_d = \\partial f / \\partial u,

which is exact for the simulator's own integrator, and the gain solves the discrete algebraic
Riccati equation (python-control ``dlqr``)

.. math::

    P = A_d^T P A_d - A_d^T P B_d (R + B_d^T P B_d)^{-1} B_d^T P A_d + Q, \\qquad
    K = (R + B_d^T P B_d)^{-1} B_d^T P A_d,

so that ``u = u_eq - K (x - a)`` minimises ``sum_t x_t^T Q x_t + u_t^T R u_t`` for the
linearised model. The *continuous* option designs on the paper's analytic ``A, B``
(appendix B) with ``lqr`` instead; it is offered for comparison only. The *authors* option is
the design the paper's numbers come from (:mod:`leoc.control.authors`): ``lqr`` with ``R = 1`` on
the authors' own models, its gain scaled by the actuator limit.

The gain acts on the state; the hybrid policy acts on the observation, where every angle is
seen through its cosine and sine. :func:`observation_gain` maps ``K`` to ``G(o) = W o + b``
linear in the observation with the same value and the same Jacobian at the operating point.

References
----------
Zhang, N. and Capel, N. (2021). LEOC: A principled method in integrating reinforcement learning
and classical control theory. L4DC, section 5.2 and appendix B.
"""

from __future__ import annotations

from typing import Literal, NamedTuple

import numpy as np
import torch

from leoc.systems.base import DTYPE, System, check_repeat

#: LQR design methods: the discrete LQR on the autodiff linearisation (default), the continuous
#: one on the paper's analytic model, or the authors' (nrjc/LEOC) continuous design.
DESIGN_METHODS = ("discrete", "continuous", "authors")
DesignMethod = Literal["discrete", "continuous", "authors"]
# Tolerances of the matrix checks (relative to the matrix scale).
SYMMETRY_RTOL = 1e-9
DEFINITENESS_RTOL = 1e-12
RANK_RTOL = 1e-9
# Scan of loop-gain factors used by :func:`stable_gain_interval`.
GAIN_SCAN_DECADES = 3.0
GAIN_SCAN_POINTS = 1201
GAIN_BISECTION_STEPS = 60


class Linearisation(NamedTuple):
    """Jacobians of the discrete step map at ``(state, action)``."""

    A_d: np.ndarray  # (S, S)
    B_d: np.ndarray  # (S, A)
    state: np.ndarray  # (S,)
    action: np.ndarray  # (A,)


class StabilityMargins(NamedTuple):
    """Classical margins of the loop broken at the plant input, ``L(z) = K (zI - A_d)^-1 B_d``.

    ``gain_margin`` and ``phase_margin`` (degrees) are python-control's ``stability_margins``:
    for an open-loop unstable plant (all three systems) the gain margin is a *lower* margin
    (the loop gain may fall to that factor). ``gain_interval`` is the exact interval of scalar
    factors k for which ``A_d - k B_d K`` stays Schur stable, found by eigenvalue scan and
    bisection; it is the clearer statement of gain robustness.
    """

    gain_margin: float
    phase_margin: float
    phase_crossover_frequency: float  # rad/s
    gain_crossover_frequency: float  # rad/s
    gain_interval: tuple[float, float]


class LQRDesign(NamedTuple):
    """Result of :func:`design_lqr` (all arrays numpy float64).

    ``K`` acts on the state deviation, ``(W, b)`` on the observation: ``G(o) = W o + b``.
    ``closed_loop_eigenvalues`` are those of ``A_d - B_d K`` (discrete, on the simulator's exact
    linearisation of the ``action_repeat``-step held map, whatever the design method).
    """

    K: np.ndarray  # (A, S)
    P: np.ndarray  # (S, S)
    closed_loop_eigenvalues: np.ndarray  # (S,) complex
    A_d: np.ndarray
    B_d: np.ndarray
    Q: np.ndarray
    R: np.ndarray
    W: np.ndarray  # (A, O)
    b: np.ndarray  # (A,)
    method: str
    margins: StabilityMargins
    action_repeat: int = 1  # control period the design is for, in simulator steps

    @property
    def spectral_radius(self) -> float:
        """Largest closed-loop eigenvalue modulus of ``A_d - B_d K`` (< 1: stable)."""
        return float(np.max(np.abs(self.closed_loop_eigenvalues)))


def linearise(
    system: System,
    state: np.ndarray | None = None,
    action: np.ndarray | None = None,
    action_repeat: int = 1,
) -> Linearisation:
    """Jacobians of the control-period map by autodiff (default: at the operating point).

    Parameters
    ----------
    system : System
    state : array of shape (S,), optional
        Defaults to ``system.operating_state``.
    action : array of shape (A,), optional
        Defaults to ``system.u_eq``.
    action_repeat : int
        Simulator steps per decision: the map linearised is ``System.step_held`` (the
        ``action_repeat``-step map with the action held); 1 is ``step_fn`` itself.
    """
    repeat = check_repeat(action_repeat)
    state_np = system.operating_state if state is None else np.asarray(state, dtype=float)
    action_np = system.u_eq if action is None else np.asarray(action, dtype=float)
    if state_np.shape != (system.state_dim,):
        raise ValueError(f"state: expected shape ({system.state_dim},), found {state_np.shape}")
    if action_np.shape != (system.action_dim,):
        raise ValueError(f"action: expected shape ({system.action_dim},), found {action_np.shape}")

    def step_single(x: torch.Tensor, u: torch.Tensor) -> torch.Tensor:
        return system.step_held(x.unsqueeze(0), u.unsqueeze(0), repeat)[0]

    jac_x, jac_u = torch.autograd.functional.jacobian(
        step_single,
        (torch.as_tensor(state_np, dtype=DTYPE), torch.as_tensor(action_np, dtype=DTYPE)),
    )
    return Linearisation(jac_x.numpy(), jac_u.numpy(), state_np.copy(), action_np.copy())


def _weight_matrix(value: object, size: int, name: str, definite: bool) -> np.ndarray:
    """Check a cost weight: square (size, size) (a vector means its diagonal), symmetric,
    positive semi-definite (``definite=False``) or positive definite (``definite=True``)."""
    matrix = np.atleast_1d(np.asarray(value, dtype=float))
    if matrix.ndim == 1:
        matrix = np.diag(matrix)
    if matrix.shape != (size, size):
        raise ValueError(
            f"{name}: expected shape ({size}, {size}) or ({size},), found {matrix.shape}"
        )
    if not np.all(np.isfinite(matrix)):
        raise ValueError(f"{name}: expected finite entries, found {matrix.tolist()}")
    scale = max(1.0, float(np.max(np.abs(matrix))))
    if not np.allclose(matrix, matrix.T, rtol=0.0, atol=SYMMETRY_RTOL * scale):
        raise ValueError(f"{name}: expected a symmetric matrix, found {matrix.tolist()}")
    smallest = float(np.min(np.linalg.eigvalsh(matrix)))
    if definite and smallest <= DEFINITENESS_RTOL * scale:
        raise ValueError(
            f"{name}: expected positive definite, found smallest eigenvalue {smallest:.3g}"
        )
    if not definite and smallest < -DEFINITENESS_RTOL * scale:
        raise ValueError(
            f"{name}: expected positive semi-definite, found smallest eigenvalue {smallest:.3g}"
        )
    return matrix


def check_stabilisable(a_matrix: np.ndarray, b_matrix: np.ndarray, discrete: bool) -> None:
    """Raise if some unstable mode of ``(A, B)`` is uncontrollable (PBH rank test).

    A mode lambda is unstable if ``|lambda| >= 1`` (discrete) or ``Re(lambda) >= 0``
    (continuous); it is controllable iff ``rank [A - lambda I, B] = n``.
    """
    size = a_matrix.shape[0]
    for eigenvalue in np.linalg.eigvals(a_matrix):
        unstable = abs(eigenvalue) >= 1.0 if discrete else eigenvalue.real >= 0.0
        if not unstable:
            continue
        pbh = np.hstack([a_matrix - eigenvalue * np.eye(size), b_matrix])
        singular = np.linalg.svd(pbh, compute_uv=False)
        if singular[-1] <= RANK_RTOL * max(1.0, singular[0]):
            raise ValueError(
                f"(A, B): not stabilisable: the unstable mode {eigenvalue:.6g} is "
                "uncontrollable (PBH rank test), so no LQR gain can stabilise it"
            )


def observation_gain(system: System, K: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Map a state gain ``K`` to ``G(o) = W o + b`` on the observation.

    ``W = -K J(a)^T`` with ``J`` the observation map's Jacobian (see
    :meth:`~leoc.systems.observation.ObservationMap.linear_gain`): a plain state entry s gets
    ``W[:, col] = -K[:, s]``. An angle s seen as
    ``(cos theta, sin theta)`` gets ``W_sin = -K_s cos a_s`` and ``W_cos = K_s sin a_s``, the
    choice that makes ``dG/dtheta = -K_s`` at ``theta = a_s`` (at a_s = 0: the gain acts on
    sin theta). Finally ``b = u_eq - W o(a)`` so that ``G(o(a)) = u_eq``.

    Returns
    -------
    W : (A, O) array
    b : (A,) array
    """
    K = np.asarray(K, dtype=float)
    if K.shape != (system.action_dim, system.state_dim):
        raise ValueError(
            f"K: expected shape ({system.action_dim}, {system.state_dim}), found {K.shape}"
        )
    W = system.observation.linear_gain(K, system.operating_state)
    W = W + 0.0  # turn the -0.0 of zero gains into 0.0 for display
    b = system.u_eq - W @ system.operating_obs
    return W, b


def stable_gain_interval(
    a_matrix: np.ndarray, b_matrix: np.ndarray, K: np.ndarray
) -> tuple[float, float]:
    """Interval ``(k_low, k_high)`` of factors k, around k = 1, with ``A - k B K`` Schur stable.

    Scanned over ``10^-3 .. 10^3`` and refined by bisection; an end at the scan edge is
    returned as 0 or inf.
    """

    def stable(factor: float) -> bool:
        return bool(np.max(np.abs(np.linalg.eigvals(a_matrix - factor * b_matrix @ K))) < 1.0)

    if not stable(1.0):
        return (float("nan"), float("nan"))
    factors = np.logspace(-GAIN_SCAN_DECADES, GAIN_SCAN_DECADES, GAIN_SCAN_POINTS)
    flags = np.array([stable(f) for f in factors])
    one = int(np.searchsorted(factors, 1.0))

    def edge(direction: int) -> float:
        index = one
        while 0 <= index + direction < len(factors) and flags[index + direction]:
            index += direction
        if index + direction < 0:
            return 0.0
        if index + direction >= len(factors):
            return float("inf")
        inside, outside = factors[index], factors[index + direction]
        for _ in range(GAIN_BISECTION_STEPS):
            middle = 0.5 * (inside + outside)
            inside, outside = (middle, outside) if stable(middle) else (inside, middle)
        return float(inside)

    return (edge(-1), edge(+1))


def loop_margins(
    a_matrix: np.ndarray, b_matrix: np.ndarray, K: np.ndarray, dt: float
) -> StabilityMargins:
    """Gain/phase margins of ``L(z) = K (zI - A)^-1 B`` (sample time ``dt``) and the exact
    stable gain interval (see :class:`StabilityMargins`)."""
    import control

    loop = control.ss(a_matrix, b_matrix, K, np.zeros((K.shape[0], b_matrix.shape[1])), dt)
    gain_margin, phase_margin, _, phase_freq, gain_freq, _ = control.stability_margins(
        loop, returnall=False
    )
    return StabilityMargins(
        float(gain_margin),
        float(phase_margin),
        float(phase_freq),
        float(gain_freq),
        stable_gain_interval(a_matrix, b_matrix, K),
    )


def design_lqr(
    system: System,
    Q: object | None = None,
    R: object | None = None,
    method: DesignMethod = "discrete",
    action_repeat: int = 1,
) -> LQRDesign:
    """Design the LQR of ``system`` about its operating point, for a control period.

    Parameters
    ----------
    system : System
    Q : array (S, S) or (S,), optional
        State weight, symmetric PSD; defaults to ``diag(system.default_q)``.
    R : array (A, A) or (A,), optional
        Action weight, symmetric PD; defaults to ``diag(system.default_r)``.
    method : {"discrete", "continuous", "authors"}
        ``discrete`` (default): ``dlqr`` on the autodiff linearisation of the step map.
        ``continuous``: ``lqr`` on the paper's analytic continuous-time ``A, B``.
        ``authors``: nrjc/LEOC's design (:func:`leoc.control.authors.authors_gain`): ``lqr``
        with their ``Q`` and ``R = 1`` on their models, times the actuator limit; ``Q`` and
        ``R`` are theirs and may not be given. ``P`` is then the discrete Lyapunov matrix of
        the closed loop at the period, :math:`A_{cl}^T P A_{cl} - P + Q + K^T R K = 0`.
    action_repeat : int
        Control period in simulator steps: the controller decides every ``action_repeat``
        steps and holds its action (PILCO: 3). The discrete design linearises that held map
        (``A_d, B_d`` of ``System.step_held``), so the gain is the LQR of the closed loop the
        controller actually runs; ``Q`` and ``R`` weigh one decision. Eigenvalues and margins
        are those of the held map (sample time ``action_repeat * dt``).

    Returns
    -------
    LQRDesign

    Raises
    ------
    ValueError
        Wrong shapes, Q not PSD, R not PD, unknown method, or a non-stabilisable pair.
    """
    import control

    if method not in DESIGN_METHODS:
        raise ValueError(f"method: expected one of {DESIGN_METHODS}, found {method!r}")
    if method == "authors":
        return _authors_design(system, Q, R, action_repeat)
    q_matrix = _weight_matrix(system.default_q if Q is None else Q, system.state_dim, "Q", False)
    r_matrix = _weight_matrix(system.default_r if R is None else R, system.action_dim, "R", True)
    lin = linearise(system, action_repeat=action_repeat)
    lin_repeat = check_repeat(action_repeat)
    if method == "discrete":
        check_stabilisable(lin.A_d, lin.B_d, discrete=True)
        K, P, _ = control.dlqr(lin.A_d, lin.B_d, q_matrix, r_matrix)
    else:
        a_cont, b_cont = system.continuous_model()
        check_stabilisable(a_cont, b_cont, discrete=False)
        K, P, _ = control.lqr(a_cont, b_cont, q_matrix, r_matrix)
    K = np.asarray(K, dtype=float)
    return _design(system, lin, lin_repeat, K, P, q_matrix, r_matrix, method)


def _design(
    system: System,
    lin: Linearisation,
    repeat: int,
    K: np.ndarray,
    P: np.ndarray,
    q_matrix: np.ndarray,
    r_matrix: np.ndarray,
    method: str,
) -> LQRDesign:
    """Assemble an :class:`LQRDesign` from a state gain: eigenvalues and margins on the held
    map ``lin``, the observation gain ``(W, b)``."""
    eigenvalues = np.linalg.eigvals(lin.A_d - lin.B_d @ K)
    W, b = observation_gain(system, K)
    margins = loop_margins(lin.A_d, lin.B_d, K, system.dt * repeat)
    return LQRDesign(
        K,
        np.asarray(P, dtype=float),
        eigenvalues,
        lin.A_d,
        lin.B_d,
        q_matrix,
        r_matrix,
        W,
        b,
        method,
        margins,
        repeat,
    )


def _authors_design(
    system: System, Q: object | None, R: object | None, action_repeat: int
) -> LQRDesign:
    """``design_lqr(method="authors")``: the gain of :func:`leoc.control.authors.authors_gain`,
    evaluated on the exact linearisation of the held map at ``action_repeat``."""
    from scipy.linalg import solve_discrete_lyapunov

    from leoc.control.authors import AUTHORS_ACTION_WEIGHT, authors_gain, authors_model

    if Q is not None or R is not None:
        raise ValueError(
            "Q, R: method 'authors' uses the authors' own weights (their Q, R = 1); "
            f"found Q={Q!r}, R={R!r}"
        )
    K = authors_gain(system)
    q_matrix = authors_model(system).Q
    r_matrix = np.full((system.action_dim, system.action_dim), AUTHORS_ACTION_WEIGHT)
    lin = linearise(system, action_repeat=action_repeat)
    closed = lin.A_d - lin.B_d @ K
    # The discrete Lyapunov matrix of the closed loop with the stage cost x^T (Q + K^T R K) x:
    # the quadratic form a region-of-attraction certificate needs (P of the Riccati equation
    # exists only for the designs that solve one at this period).
    P = solve_discrete_lyapunov(closed.T, q_matrix + K.T @ r_matrix @ K)
    repeat = check_repeat(action_repeat)
    return _design(system, lin, repeat, K, 0.5 * (P + P.T), q_matrix, r_matrix, "authors")
