"""Export a loaded controller's whole decision as ONNX or TorchScript, checked on export.

The exported model is :class:`~leoc.deploy.Decision`: one float64 observation batch
``observation`` ``(B, O)`` in, the saturated action ``action`` ``(B, A)`` out (learned part,
relevance, linear part, blend, squash and the actuator's clip, as trained). Everything the
model cannot say is in a JSON file beside it (:func:`export_metadata`): the control period
(the hold), the observation and action layouts with their units and limits, the LQR design,
the hybrid spec and the certificate the relevance was built on.

The check (:func:`check_export`) runs the exported bytes (ONNX Runtime, or ``torch.jit.load``)
on observations of the operating region and of the swing-up region
(:func:`check_observations`) and compares each action with torch's:
``|a_exported - a_torch| <= rtol * max(1, |a_torch|)`` entrywise, ``rtol`` = 1e-6 by default.
An export that fails it is not written.
"""

from __future__ import annotations

import contextlib
import io
import math
import warnings
from pathlib import Path
from typing import TYPE_CHECKING, Any, NamedTuple

import numpy as np
import torch

if TYPE_CHECKING:
    from .controller import DeployedController

__all__ = [
    "CHECK_COUNT",
    "CHECK_RTOL",
    "EXPORT_FORMATS",
    "ExportCheck",
    "ExportResult",
    "check_export",
    "check_observations",
    "export_controller",
    "export_metadata",
    "metadata_path",
]

#: What ``leoc export --format`` accepts.
EXPORT_FORMATS = ("onnx", "torchscript")
#: Observations the export is checked on (half operating region, half swing-up region).
CHECK_COUNT = 100_000
#: Relative bound of the check: ``|a - b| <= CHECK_RTOL * max(1, |b|)``, ``b`` torch's action.
CHECK_RTOL = 1e-6
#: The ONNX opset written (ONNX Runtime 1.18 and later run it).
ONNX_OPSET = 17
_SUFFIX = {"onnx": ".onnx", "torchscript": ".pt"}
_INSTALL_HINT = "pip install 'leoc[deploy]' (or pip install onnx onnxruntime)"
_INPUT, _OUTPUT = "observation", "action"


class ExportCheck(NamedTuple):
    """The exported model against torch on ``count`` observations.

    ``max_error`` is the largest ``|a - b| / max(1, |b|)`` (``a`` exported, ``b`` torch);
    ``passed`` is ``max_error <= rtol``.
    """

    count: int
    max_error: float
    rtol: float
    passed: bool

    def describe(self, runtime: str) -> str:
        """One line: ``check: N observations, max |a - b| / max(1, |b|) = ... <= 1e-06``."""
        verdict = "<=" if self.passed else "> "
        return (
            f"check: {self.count} observations (operating region and swing-up region), "
            f"{runtime} against torch: max |a - b| / max(1, |b|) = {self.max_error:.3g} "
            f"{verdict} {self.rtol:g}: {'passed' if self.passed else 'FAILED'}"
        )


class ExportResult(NamedTuple):
    """What :func:`export_controller` wrote and how its check went."""

    model: Path
    metadata: Path
    check: ExportCheck


def _require_onnxruntime() -> Any:
    """``onnxruntime``, or an ImportError naming the extra to install."""
    try:
        import onnxruntime
    except ImportError as error:
        raise ImportError(f"onnxruntime is not installed: {_INSTALL_HINT}") from error
    return onnxruntime


def metadata_path(model: str | Path) -> Path:
    """The metadata file of an exported model: the model's path with ``.json`` added."""
    model = Path(model)
    return model.with_name(model.name + ".json")


def check_observations(
    controller: DeployedController, count: int = CHECK_COUNT, seed: int = 0
) -> np.ndarray:
    """``count`` float64 observations ``(count, O)``: half of states drawn uniformly from the
    operating region (``system.sample_operating_region``), half of the states the controller's
    own closed loop visits from swing-up starts (``system.sample_start``), observed through the
    system's observation map."""
    from leoc.systems.rollout import simulate

    system = controller.system
    rng = np.random.default_rng(seed)
    near = system.sample_operating_region(rng, count // 2)
    steps = int(system.episode_steps)
    episodes = -(-(count - near.shape[0]) // (steps + 1))
    starts = np.stack([system.sample_start(rng) for _ in range(episodes)])
    loop = simulate(system, controller.module, starts, steps, action_repeat=controller.period_steps)
    visited = loop.states
    visited = visited.reshape(-1, system.state_dim)[: count - near.shape[0]]
    states = torch.as_tensor(np.concatenate([near, visited]), dtype=torch.float64)
    return system.observe(states).numpy()


def model_bytes(controller: DeployedController, fmt: str) -> bytes:
    """The serialised decision of ``controller`` in ``fmt`` (float64 in and out)."""
    from unittest import mock

    module = controller.module
    example = torch.as_tensor(controller.system.operating_obs, dtype=torch.float64)[None]
    buffer = io.BytesIO()
    # ONNX Runtime's CPU Atan has no float64 kernel: the ONNX graph computes atan2 (the ROA
    # relevance's angle) from operations that have one (exportable_atan2); the check below
    # compares it with torch's own
    patch = mock.patch.object(torch, "atan2", exportable_atan2) if fmt == "onnx" else None
    with torch.no_grad(), patch or contextlib.nullcontext(), warnings.catch_warnings():
        # the tracer warns that the hybrid's input checks are constants of the trace: they are;
        # torch 2.13 marks torch.jit and the TorchScript-based ONNX exporter deprecated, and
        # they are what runs without onnxscript (the check below vouches for their output)
        warnings.simplefilter("ignore", torch.jit.TracerWarning)
        warnings.simplefilter("ignore", DeprecationWarning)
        if fmt == "torchscript":
            # traced, not scripted: the decision has no data-dependent control flow, and the
            # input checks of the hybrid are Python run once at trace time
            torch.jit.save(torch.jit.trace(module, example), buffer)
        else:
            _export_onnx(module, example, buffer)
    return buffer.getvalue()


def _export_onnx(module: torch.nn.Module, example: torch.Tensor, buffer: io.BytesIO) -> None:
    """``module`` as ONNX into ``buffer``: float64 in, out and throughout."""
    # The TorchScript-based exporter (dynamo=False): the dynamo exporter needs the onnxscript
    # package, which the 'deploy' extra does not install; this one writes the float64 graph as
    # traced, with a dynamic batch axis. Its scalar type analysis casts products of 0-d
    # tensors (the Lyapunov relevance's lambda * rho) to the default dtype: float64 here, or
    # rho would be rounded to float32 (a relative error of 2e-8 in the action).
    default = torch.get_default_dtype()
    torch.set_default_dtype(torch.float64)
    try:
        torch.onnx.export(
            module,
            (example,),
            buffer,
            dynamo=False,
            opset_version=ONNX_OPSET,
            input_names=[_INPUT],
            output_names=[_OUTPUT],
            dynamic_axes={_INPUT: {0: "batch"}, _OUTPUT: {0: "batch"}},
        )
    finally:
        torch.set_default_dtype(default)


#: Terms of the arctangent series on [0, tan(pi / 16)]: the first term left out is below
#: 0.2^23 / 23 < 1e-17.
ATAN_SERIES_TERMS = 11
_ATAN_COEFFICIENTS = tuple((-1.0) ** k / (2 * k + 1) for k in range(ATAN_SERIES_TERMS))


def exportable_atan2(y: torch.Tensor, x: torch.Tensor) -> torch.Tensor:
    r"""``atan2(y, x)`` from square roots, divisions and a polynomial (float64 to about
    1e-15), for ONNX Runtime, whose Atan has no float64 kernel.

    The angle of ``(|x|, |y|)`` in :math:`[0, \pi/2]` is :math:`2 \arctan t`,
    :math:`t = |y| / (r + |x|) \in [0, 1]`; two half-angle steps
    :math:`t \mapsto t / (1 + \sqrt{1 + t^2})` bring :math:`t` into
    :math:`[0, \tan(\pi/16)]`, where the series converges fast; the quadrant is restored
    from the signs of ``x`` and ``y`` (``atan2(-0.0, x < 0)`` gives :math:`+\pi` here,
    :math:`-\pi` in torch: the same wrapped angle).
    """
    ax, ay = torch.abs(x), torch.abs(y)
    denominator = torch.sqrt(ax * ax + ay * ay) + ax
    t = ay / torch.where(denominator > 0, denominator, torch.ones_like(denominator))
    for _ in range(2):
        t = t / (1.0 + torch.sqrt(1.0 + t * t))
    square = t * t
    series = torch.full_like(t, _ATAN_COEFFICIENTS[-1])
    for coefficient in reversed(_ATAN_COEFFICIENTS[:-1]):
        series = series * square + coefficient
    first_quadrant = 8.0 * t * series
    angle = torch.where(x < 0, math.pi - first_quadrant, first_quadrant)
    return torch.where(y < 0, -angle, angle)


def run_exported(data: bytes, fmt: str, observations: np.ndarray) -> np.ndarray:
    """Actions of the serialised model ``data`` on ``observations`` (ONNX Runtime on one
    thread, or the TorchScript module)."""
    if fmt == "torchscript":
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", DeprecationWarning)  # torch.jit.load in torch 2.13
            module = torch.jit.load(io.BytesIO(data))
        with torch.no_grad():
            return module(torch.as_tensor(observations, dtype=torch.float64)).numpy()
    onnxruntime = _require_onnxruntime()
    options = onnxruntime.SessionOptions()
    options.intra_op_num_threads = 1
    session = onnxruntime.InferenceSession(data, options, providers=["CPUExecutionProvider"])
    return session.run([_OUTPUT], {_INPUT: np.ascontiguousarray(observations, np.float64)})[0]


def check_export(
    data: bytes,
    fmt: str,
    controller: DeployedController,
    observations: np.ndarray,
    rtol: float = CHECK_RTOL,
) -> ExportCheck:
    """The serialised ``data`` against ``controller.act`` on ``observations``: passed when
    ``|a - b| <= rtol * max(1, |b|)`` for every entry (``a`` exported, ``b`` torch)."""
    exported = run_exported(data, fmt, observations)
    reference = controller.act(observations)
    if exported.shape != reference.shape:
        return ExportCheck(len(observations), float("inf"), rtol, False)
    error = np.abs(exported - reference) / np.maximum(1.0, np.abs(reference))
    worst = float(np.max(error)) if error.size else 0.0
    passed = bool(np.all(np.isfinite(exported))) and worst <= rtol
    return ExportCheck(len(observations), worst, rtol, passed)


def _check_target(path: Path, fmt: str, overwrite: bool) -> None:
    """Refuse an unknown format or an existing file (unless ``overwrite``), in one line."""
    if fmt not in EXPORT_FORMATS:
        raise ValueError(f"--format: expected one of {EXPORT_FORMATS}, found {fmt!r}")
    for existing in (path, metadata_path(path)):
        if existing.is_dir():
            raise ValueError(f"--out: expected a file path, found the folder {str(existing)!r}")
        if existing.exists() and not overwrite:
            raise ValueError(
                f"--out: expected a path that does not exist (or --overwrite), found "
                f"{str(existing)!r}"
            )


def export_controller(
    controller: DeployedController,
    path: str | Path,
    fmt: str = "onnx",
    overwrite: bool = False,
    count: int = CHECK_COUNT,
    seed: int = 0,
) -> ExportResult:
    """Write ``controller``'s decision to ``path`` in ``fmt`` with its metadata beside it
    (:func:`metadata_path`), after checking it (:func:`check_export`) on ``count``
    observations (:func:`check_observations` with ``seed``). Both files are written
    atomically (the model, then its metadata), and only when the check passed.

    Raises
    ------
    ValueError
        An unknown ``fmt``, an existing file without ``overwrite``, or a failed check (the
        message gives its figures; nothing is written).
    ImportError
        ONNX Runtime is missing (``pip install 'leoc[deploy]'``).
    """
    from leoc.io import write_bytes_atomic, write_json_atomic

    path = Path(path)
    _check_target(path, fmt, overwrite)
    if fmt == "onnx":
        _require_onnxruntime()
    data = model_bytes(controller, fmt)
    check = check_export(data, fmt, controller, check_observations(controller, count, seed))
    if not check.passed:
        raise ValueError(f"export: {check.describe(_runtime(fmt))}; nothing written")
    write_bytes_atomic(path, data)
    metadata = export_metadata(controller, path, fmt, check)
    return ExportResult(path, write_json_atomic(metadata_path(path), metadata), check)


def _runtime(fmt: str) -> str:
    return "ONNX Runtime" if fmt == "onnx" else "TorchScript"


def export_metadata(
    controller: DeployedController, path: Path, fmt: str, check: ExportCheck
) -> dict[str, Any]:
    """What the exported model needs beside it: format and tensors, the hold, the layouts
    with units and limits, the LQR design, the hybrid spec and the certificate."""
    import leoc

    system = controller.system
    return {
        "format": fmt,
        "model": path.name,
        "leoc_version": leoc.__version__,
        "source": controller.source,
        "system": system.name,
        "dtype": "float64",
        "input": {"name": _INPUT, "shape": ["batch", controller.obs_dim]},
        "output": {"name": _OUTPUT, "shape": ["batch", controller.action_dim]},
        "control_period": {
            "steps": controller.period_steps,
            "seconds": controller.period,
            "simulator_dt": float(system.dt),
            "hold": "zero-order: apply each action for 'seconds', then decide again",
        },
        "observation": observation_layout(system),
        "action": action_layout(system),
        "operating_point": {
            "state": system.operating_state.tolist(),
            "observation": system.operating_obs.tolist(),
            "action": system.u_eq.tolist(),
        },
        "lqr": _design_record(controller.design),
        "hybrid": None if controller.hybrid_spec is None else controller.hybrid_spec.to_dict(),
        "saturation": controller.saturation,
        "certificate": _certificate_record(controller),
        "check": {**check._asdict(), "bound": "|a - b| <= rtol * max(1, |b|)"},
    }


def observation_layout(system: Any) -> list[dict[str, Any]]:
    """One entry per observation column: its name, unit and how it is made from the state
    (``cos``/``sin`` of an angle state, or a state as is)."""
    from leoc.systems.units import state_units

    units = state_units(system)
    layout = []
    for component in system.obs_layout:
        name = system.state_names[component.state_index]
        trig = component.kind in ("cos", "sin")
        layout.append(
            {
                "name": f"{component.kind}({name})" if trig else name,
                "unit": "" if trig else units[component.state_index],
                "kind": component.kind,
                "state": name,
            }
        )
    return layout


def action_layout(system: Any) -> list[dict[str, Any]]:
    """One entry per action: the actuator's limits (the model's output stays inside them)."""
    limit = float(system.action_limit)
    return [
        {"name": f"u{index}", "low": -limit, "high": limit, "equilibrium": float(u)}
        for index, u in enumerate(system.u_eq)
    ]


def _design_record(design: Any) -> dict[str, Any]:
    """The LQR design: ``G(o) = W o + b`` on the observation, ``u = -K z`` on the state."""
    return {
        "method": design.method,
        "action_repeat": int(design.action_repeat),
        "W": np.asarray(design.W).tolist(),
        "b": np.asarray(design.b).tolist(),
        "K": np.asarray(design.K).tolist(),
        "P": np.asarray(design.P).tolist(),
        "Q": np.asarray(design.Q).tolist(),
        "R": np.asarray(design.R).tolist(),
        "spectral_radius": design.spectral_radius,
    }


def _certificate_record(controller: DeployedController) -> dict[str, Any] | None:
    """The certificate the relevance was built on: ``{z : z^T P z <= rho}`` about the
    operating state (angles wrapped), at the control period; None when it has none."""
    certificate = controller.certificate
    if certificate is None:
        return None
    # the ROA relevance's flat top {V <= rho_in}: there r = 1 and the model is the LQR
    flat_top = next((m.rho_in for m in controller.module.modules() if hasattr(m, "rho_in")), None)
    return {
        "statement": "V(z) = z^T P z <= rho is a region of attraction of the saturated LQR",
        "flat_top_rho": None if flat_top is None else float(flat_top),
        "rho": float(certificate.rho),
        "basis": certificate.basis,
        "P": np.asarray(certificate.P).tolist(),
        "operating_state": np.asarray(certificate.operating_state).tolist(),
        "angle_indices": list(certificate.angle_indices),
        "action_repeat": int(certificate.action_repeat),
    }
