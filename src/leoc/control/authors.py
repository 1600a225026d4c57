r"""The authors' linear design: nrjc/LEOC's continuous-time LQR, as the paper's numbers use it.

The paper's "Linear" controller (Zhang & Capel, L4DC 2021, appendix D) is the authors' PILCO
``LinearController`` (nrjc/LEOC ``pilco/controllers.py``): :math:`u = u_{max} \sin(W o)` applied
every simulator step, with :math:`W` the gain of ``control.lqr(A, B, Q, R=1)`` (``dao/
controller_utils.py``, ``LQR.get_W_matrix``) on each environment's own linearisation
``env.control()`` (``dao/envs/*_env.py``), reordered onto the observation by
``LQR.get_k_prime`` (an angle's gain on its sine column, zero on its cosine). Their DDPG hybrid
blends on the normalised action and scales by :math:`u_{max}` afterwards (``scale_to_spec``),
with the same effect: in physical units the small-signal gain is :math:`u_{max} K`, twice to
three times the LQR gain of their own model.

The models differ from leoc's :meth:`~leoc.systems.base.System.continuous_model` in ways that
matter:

* every ``B`` has the opposite sign (their input enters as :math:`-u`), which with their
  :math:`u = +W o` gives the same closed loop as :math:`u = -K x` on leoc's sign convention;
* the cart-pole's ``A[1, 2]`` is :math:`+m^2 g l^2 / p` where the equations of motion give
  :math:`-m^2 g l^2 / p`;
* the mountain car's ``A[1, 0]`` is :math:`g`, not :math:`1.35 g` (the hill's curvature);
* the cart-pole's and mountain car's ``Q`` are ``diag(2, .3, 2, .3)`` and ``diag(2, .3)``, the
  pendulum's ``diag(2, 2)``; ``R = 1`` everywhere.

:func:`authors_gain` returns the state gain in leoc's convention (:math:`u = u_{eq} - K (x - a)`
near ``a``) with the :math:`u_{max}` factor included, so that ``observation_gain`` gives the
authors' :math:`u_{max} W` and a sine squash :math:`u_{max} \sin(z / u_{max})` gives their
controller exactly.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple

import numpy as np

from leoc.systems.base import System

__all__ = ["AUTHORS_MODELS", "AuthorsModel", "authors_gain", "authors_model"]

# R = 1 in LQR.get_W_matrix (nrjc/LEOC dao/controller_utils.py).
AUTHORS_ACTION_WEIGHT = 1.0


class AuthorsModel(NamedTuple):
    """One environment's ``control()`` of nrjc/LEOC: continuous ``A`` (S, S), ``B`` (S, 1) in
    their sign convention (input ``-u``), and the state weight ``Q`` (S, S)."""

    A: np.ndarray
    B: np.ndarray
    Q: np.ndarray


def _pendulum(system: System) -> AuthorsModel:
    """``dao/envs/pendulum_env.py`` ``SwingUpEnv.control``: rod of half-length l/2 about its
    centre, I = m (l/2)^2 / 3, p = m (l/2)^2 + I; Q = diag(2, 2)."""
    params = system.params
    half = params.length / 2.0  # type: ignore[attr-defined]
    mass, gravity = params.mass, params.gravity  # type: ignore[attr-defined]
    inertia = mass * half**2 / 3.0
    p = mass * half**2 + inertia
    a_matrix = np.array([[0.0, 1.0], [mass * half * gravity / p, 0.0]])
    b_matrix = np.array([[0.0], [-1.0 / p]])
    return AuthorsModel(a_matrix, b_matrix, np.diag([2.0, 2.0]))


def _cartpole(system: System) -> AuthorsModel:
    """``dao/envs/cartpole_env.py`` ``CartPoleEnv.control``: I = m l^2 / 3,
    p = I (M + m) + M m l^2, frictionless; Q = diag(2, 0.3, 2, 0.3)."""
    params = system.params
    cart, pole = params.cart_mass, params.pole_mass  # type: ignore[attr-defined]
    half, gravity = params.half_length, params.gravity  # type: ignore[attr-defined]
    inertia = pole * half**2 / 3.0
    p = inertia * (cart + pole) + cart * pole * half**2
    a_matrix = np.zeros((4, 4))
    a_matrix[0, 1] = 1.0
    a_matrix[2, 3] = 1.0
    a_matrix[1, 2] = pole**2 * gravity * half**2 / p
    a_matrix[3, 2] = pole * gravity * half * (cart + pole) / p
    b_matrix = np.array([[0.0], [-(inertia + pole * half**2) / p], [0.0], [pole * half / p]])
    return AuthorsModel(a_matrix, b_matrix, np.diag([2.0, 0.3, 2.0, 0.3]))


def _mountaincar(system: System) -> AuthorsModel:
    """``dao/envs/mountaincar_env.py`` ``ContinuousMountainCarEnv.control``: A = [[0, 1],
    [g, 0]] (the hill's 1.35 curvature factor left out), B = [[0], [-1/m]]; Q = diag(2, 0.3)."""
    params = system.params
    a_matrix = np.array([[0.0, 1.0], [params.gravity, 0.0]])  # type: ignore[attr-defined]
    b_matrix = np.array([[0.0], [-1.0 / params.mass]])  # type: ignore[attr-defined]
    return AuthorsModel(a_matrix, b_matrix, np.diag([2.0, 0.3]))


AUTHORS_MODELS: dict[str, Callable[[System], AuthorsModel]] = {
    "pendulum": _pendulum,
    "cartpole": _cartpole,
    "mountaincar": _mountaincar,
}
"""The systems nrjc/LEOC linearised by hand, by registry name."""


def authors_model(system: System) -> AuthorsModel:
    """The authors' ``env.control()`` model of ``system`` (from its current parameters).

    Raises
    ------
    ValueError
        For a system the authors had no model of (anything but the paper's three).
    """
    if system.name not in AUTHORS_MODELS:
        raise ValueError(
            f"system: the authors' linearisation exists for {sorted(AUTHORS_MODELS)} only, "
            f"found {system.name!r}; use method='discrete' or 'continuous' for other systems"
        )
    return AUTHORS_MODELS[system.name](system)


def authors_gain(system: System) -> np.ndarray:
    r"""State gain ``K`` (1, S), leoc's convention, of the authors' linear controller.

    With :math:`K_c` from ``control.lqr(A, B, Q, 1)`` on :func:`authors_model` (their input
    :math:`-u`, their control :math:`u = +K_c x` near ``a``), the physical controller near ``a``
    is :math:`u = u_{max} K_c x`, i.e. :math:`K = -u_{max} K_c` for
    :math:`u = u_{eq} - K (x - a)`.
    """
    import control

    model = authors_model(system)
    gain, _, _ = control.lqr(model.A, model.B, model.Q, AUTHORS_ACTION_WEIGHT)
    return -system.action_limit * np.asarray(gain, dtype=float)
