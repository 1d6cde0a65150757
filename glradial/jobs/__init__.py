"""Jobs over many inputs: inputs expanded, a manifest that lets a rerun skip complete work, local
worker processes or Ray actors, retries, the report (``glradial correct ... --out-dir DIR``)."""

from __future__ import annotations

from typing import TYPE_CHECKING

from ..lazy import attach

if TYPE_CHECKING:
    from .inputs import expand_inputs
    from .manifest import Manifest
    from .pool import ProcessRunner
    from .ray_runner import RayRunner
    from .report import write_report
    from .runner import JobSummary, run_job
    from .tasks import JOB_COMMANDS, CommandWork, planned_outputs

__getattr__, __dir__, __all__ = attach(__name__, __file__)
