"""Input conversion and validation shared by the policy modules.

Every user-facing argument is converted once and checked by one of these helpers, which raise
``TypeError`` (wrong kind of object) or ``ValueError`` (right kind, wrong value or shape) with a
message naming the argument, what was expected and what was found.
"""

from __future__ import annotations

import numbers

import numpy as np
import torch
from torch import Tensor

__all__ = [
    "as_float_tensor",
    "as_point",
    "check_finite",
    "check_flag",
    "check_last_dim",
    "check_positive",
    "check_positive_int",
    "check_shape",
    "register_learnable",
    "shape_str",
]


def shape_str(shape: tuple[int, ...] | torch.Size) -> str:
    """Format a shape as ``(2, 3)``; a 1-tuple as ``(3,)`` and a scalar as ``()``."""
    return str(tuple(int(size) for size in shape))


def as_float_tensor(value: object, name: str, dtype: torch.dtype) -> Tensor:
    """Convert ``value`` to a fresh floating tensor that does not alias the caller's data.

    Parameters
    ----------
    value : array-like, Tensor or number
        The user's input.
    name : str
        Argument name used in error messages.
    dtype : torch.dtype
        Floating dtype of the result.

    Returns
    -------
    Tensor
        A detached copy of ``value`` in ``dtype`` (same device if ``value`` is a tensor).
    """
    if not (isinstance(dtype, torch.dtype) and dtype.is_floating_point):
        raise TypeError(f"dtype must be a floating torch.dtype, found {dtype!r}")
    if isinstance(value, (str, bytes)) or value is None:
        raise TypeError(f"{name} must be array-like of numbers, found {type(value).__name__}")
    try:
        tensor = torch.as_tensor(value, dtype=dtype)
    except (TypeError, ValueError, RuntimeError) as exc:
        raise TypeError(
            f"{name} must be array-like of numbers, found {type(value).__name__}"
        ) from exc
    return tensor.detach().clone()


def check_shape(tensor: Tensor, name: str, expected: tuple[int, ...], letters: str) -> None:
    """Raise ``ValueError`` unless ``tensor.shape == expected``.

    ``letters`` names the dimensions, e.g. ``"(F, D)"``, so the message reads
    ``W must have shape (F, D) = (1, 3), found (3,)``.
    """
    if tuple(tensor.shape) != tuple(expected):
        raise ValueError(
            f"{name} must have shape {letters} = {shape_str(expected)}, "
            f"found {shape_str(tensor.shape)}"
        )


def check_finite(tensor: Tensor, name: str) -> None:
    """Raise ``ValueError`` if any entry of ``tensor`` is NaN or infinite."""
    if not bool(torch.isfinite(tensor).all()):
        raise ValueError(f"{name} must be finite, found {tensor.tolist()}")


def check_positive(tensor: Tensor, name: str) -> None:
    """Raise ``ValueError`` unless every entry of ``tensor`` is finite and strictly positive."""
    if not bool((torch.isfinite(tensor) & (tensor > 0)).all()):
        raise ValueError(f"{name} must be positive and finite, found {tensor.tolist()}")


def check_positive_int(value: object, name: str) -> int:
    """Return ``value`` as ``int`` if it is a positive integer (``bool`` is rejected)."""
    if isinstance(value, bool) or not isinstance(value, (numbers.Integral, np.integer)):
        raise TypeError(f"{name} must be a positive int, found {type(value).__name__}")
    if int(value) <= 0:
        raise ValueError(f"{name} must be a positive int, found {int(value)}")
    return int(value)


def check_last_dim(x: Tensor, dim: int, dtype: torch.dtype | None = None, name: str = "x") -> None:
    """Raise unless ``x`` is a tensor (of ``dtype``, if given) whose last dimension is ``dim``.

    Modules do not cast their input silently: a float32 observation fed to a float64 policy
    is reported here rather than as a matmul dtype error deep inside. A tensor-like object
    that dispatches torch functions (``__torch_function__``, e.g. an interval enclosure of
    :mod:`leoc.control.intervals`) passes as a tensor.
    """
    if not torch.overrides.is_tensor_like(x):
        raise TypeError(f"{name} must be a torch.Tensor, found {type(x).__name__}")
    if dtype is not None and x.dtype != dtype:
        raise TypeError(
            f"{name} must have the module's dtype {dtype} (convert with {name}.to({dtype})), "
            f"found {x.dtype}"
        )
    if x.dim() == 0 or x.shape[-1] != dim:
        raise ValueError(
            f"{name} must have shape (..., D) with D = {dim}, found {shape_str(x.shape)}"
        )


def scalar_or_vector(
    value: object, name: str, size: int, size_label: str, dtype: torch.dtype
) -> Tensor:
    """``value`` as a tensor of shape () or (size,); ``size_label`` names the dimension in the
    message ("D" or "F")."""
    tensor = as_float_tensor(value, name, dtype)
    if tensor.shape not in (torch.Size([]), (size,)):
        raise ValueError(
            f"{name} must be a scalar or have shape ({size_label},) = ({size},), "
            f"found {shape_str(tensor.shape)}"
        )
    return tensor


def positive_scalar_or_vector(
    value: object, name: str, size: int, size_label: str, dtype: torch.dtype
) -> Tensor:
    """:func:`scalar_or_vector`, positive and finite."""
    tensor = scalar_or_vector(value, name, size, size_label, dtype)
    check_positive(tensor, name)
    return tensor


def check_flag(value: object, name: str) -> bool:
    """``value`` if it is a bool; ``TypeError`` naming ``name`` otherwise."""
    if not isinstance(value, bool):
        raise TypeError(f"{name} must be a bool, found {type(value).__name__}")
    return value


def as_point(value: object, name: str, dtype: torch.dtype, letter: str = "D") -> Tensor:
    """``value`` as a finite vector (``letter``,) of ``dtype`` (an operating point)."""
    point = as_float_tensor(value, name, dtype)
    if point.ndim != 1:
        raise ValueError(f"{name} must have shape ({letter},), found {tuple(point.shape)}")
    check_finite(point, name)
    return point


def register_learnable(module: torch.nn.Module, name: str, value: Tensor, learn: bool) -> None:
    """``module.name = value``: an ``nn.Parameter`` if ``learn`` (training changes it), else a
    buffer (saved with the module, frozen)."""
    if learn:
        module.register_parameter(name, torch.nn.Parameter(value))
    else:
        module.register_buffer(name, value)
