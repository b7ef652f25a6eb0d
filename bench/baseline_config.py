"""What the benches' ``--baseline`` runs: the legacy planner configuration.

Imported by the bench scripts (which run with ``bench/`` on ``sys.path``); the helpers every bench shares (the load
average, ``loadavg_text``; commit; results records) are in ``_common.py``.
"""

from __future__ import annotations

import dataclasses

from helireach_ros.core.ocp.compiled_nlp import CodegenSettings
from helireach_ros.core.ocp.settings import PlannerSettings

__all__ = [
    "LEGACY_CONFIGURATION",
    "baseline_codegen",
    "baseline_settings",
    "six_state_settings",
    "with_mumps",
]

LEGACY_CONFIGURATION = {"warm_start_bound_push": 1e-6, "warm_bound_push": 1e-2, "closed_form_states": False}
"""The legacy warm-solver options (``bound_push``/``bound_frac`` IPOPT's defaults) and the legacy NLP, all six
states as variables."""


def baseline_settings(settings: PlannerSettings) -> PlannerSettings:
    """``settings`` with the legacy warm-solver options and NLP."""
    return settings.replace(**LEGACY_CONFIGURATION)


def six_state_settings(settings: PlannerSettings) -> PlannerSettings:
    """``settings`` with all six states as NLP variables (``closed_form_states`` off): the NLP before
    distance and engine power went into closed form."""
    return settings.replace(closed_form_states=False)


def baseline_codegen() -> CodegenSettings:
    """Plain CasADi functions and MUMPS: the legacy configuration's NLP functions and linear solver."""
    return CodegenSettings(mode="off", linear_solver="mumps")


def with_mumps(codegen: CodegenSettings) -> CodegenSettings:
    """``codegen`` with MUMPS as IPOPT's linear solver (the current configuration before the block LDL^T)."""
    return dataclasses.replace(codegen, linear_solver="mumps")

