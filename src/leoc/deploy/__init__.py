"""Deploy a trained controller: one loader, export to ONNX or TorchScript, and its check.

:func:`leoc.deploy.load` (also ``leoc.load``) returns a
:class:`leoc.deploy.DeployedController`: the whole decision of a run folder (or of a system's
LQR alone), observation in, saturated action out, with its control period, system, LQR design,
hybrid spec and certificate. :func:`leoc.deploy.export_controller` (``leoc export``) writes
that decision as one ONNX or TorchScript model with a JSON metadata file beside it, and checks
the exported model against torch (:func:`leoc.deploy.check_export`).

See ``docs/user_guide/deploy.md``.
"""

from __future__ import annotations

from .controller import Decision, DeployedController, load, output_saturation
from .export import (
    EXPORT_FORMATS,
    ExportCheck,
    ExportResult,
    check_export,
    check_observations,
    export_controller,
    export_metadata,
    metadata_path,
)

__all__ = [
    "EXPORT_FORMATS",
    "Decision",
    "DeployedController",
    "ExportCheck",
    "ExportResult",
    "check_export",
    "check_observations",
    "export_controller",
    "export_metadata",
    "load",
    "metadata_path",
    "output_saturation",
]
