"""H-V envelopes: the data model, the file format, loading with checks, and queries (ROS-free, numpy only).

An envelope holds, for one airframe, planner settings and power-loss level, the landing analysis of
every node of a (height above ground, forward speed) grid of level-trim states: status, optimal
value, time to land, solver statistics and the plan itself (compactly, to warm-start or publish a
fallback), plus the refined safe/unsafe boundary points. It is computed by
:mod:`helireach_ros.core.envelope.compute`.

File format (``.npz``, one file per envelope, self-describing):

* a NumPy ``.npz`` archive (zip, deflate) of plain numeric arrays — loaded with
  ``allow_pickle=False``, so a file cannot execute code;
* ``metadata_json``: UTF-8 JSON (uint8 array) with the format name and version, grid units, the
  airframe's full parameters and digest, the planner settings, method, power fraction, software
  versions, the command that produced it, timings and counts, and the status-code legend;
* ``checksum``: SHA-256 over the metadata and every array (name, dtype, shape, bytes). A truncated or
  corrupt file fails the zip CRC or this checksum and is refused with :class:`EnvelopeError`.

Per-node plans (format version 3) are stored as the node's state at the failure (``plan_initial_state``, float64)
and the plan's control function (breakpoints and values, float32: what a fallback flies, never a safety claim),
enough to warm-start the planner, which flies the function from that state to rebuild the NLP's
primal point (:class:`~helireach_ros.core.planning.planner.ControlFunctionWarmStart`). IPOPT's solution itself (the
*solver state*: primal and both multiplier vectors, float32, :data:`SOLVER_STATE_ARRAYS`) is 90 % of the bytes
and changes whenever the NLP does, so a complete file leaves it out: :func:`save_envelope` writes it to the user
cache (:func:`solver_state_path`, keyed by the answers' checksum) and :func:`read_envelope_file` attaches it when
it is there (a faster warm start; docs/decisions/warm-start-storage.md). A partial file keeps it, for
``--resume``. Files of versions 1 and 2 hold the solver state in the file and keep loading.

**3-D envelopes** (format version 2) add a climb-rate axis: ``climb_rates`` (m/s, positive up, ascending)
and every per-node array has a leading climb axis (C × H × S); the boundary points carry the index of
their slice (``boundary_slice``; refinement is within a slice). Each slice is the 2-D envelope of the
states trimmed on that flight path. A node whose (speed, climb rate) has no steady powered flight
(:func:`~helireach_ros.core.aircraft.model.trim_flight` refuses it, e.g. a descent faster than the fuselage's terminal
descent) is stored as ``no_trim``: no state to start from, never safe. 2-D files (format version 1) are
read unchanged; a 2-D envelope is a 3-D one with one slice at level flight.

Query semantics are conservative. A state is ``safe`` only if every grid node enclosing it is safe
(on a node: that node; on a grid line: its two end nodes; inside a cell: its four corners; in a 3-D
envelope the same in all three axes, up to eight nodes); outside the grid it is ``outside``. Along the
climb axis the grid is the envelope's validity domain (:meth:`ValidityDomain.climb_rate_range
<helireach_ros.core.envelope.domain.ValidityDomain.climb_rate_range>`): a 3-D file's climb-rate range
exactly, a 2-D (or one-slice) file its slice ± the level-trim tolerance; a climb rate outside it is
``outside``. The margin is the signed distance, in the (ft, kt) plane where 1 ft and 1 kt count as one
unit, to the boundary of the set that is not proven safe under that same rule: positive for safe states,
negative otherwise, so margin > 0 exactly when the status is ``safe``. Between two climb slices that set
is the union of both slices' (a node of the plane is safe only if it is safe in both), so the margin is
the 2-D margin of the combined slice. The margin does not measure along the climb axis. The refined
boundary points are reported and plotted, but never used to call a state safe.

**Robust verdicts** (optional arrays, :mod:`helireach_ros.core.robustness.envelope_verdicts`): ``robust_code`` per node
(:data:`ROBUST_CODES`) says whether a nominally safe node's landing also holds, closed loop, in every model of a
design of the uncertainty set. ``query(..., verdict="robust")`` answers by the same node rule with a safe node
that is not robust counted as ``not_robust`` (between ``safe`` and ``unverified`` in conservatism), and its
margin is to the set not proven *robustly* safe; where an enclosing node has no robust verdict
(``not_computed``, or a file without the arrays) it answers with the nominal verdict and says so
(:attr:`EnvelopeQuery.verdict`). A file with these arrays is read by older software unchanged (extra arrays).
"""

from __future__ import annotations

import copy
import dataclasses
import hashlib
import io
import json
import logging
import math
import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from helireach_ros.core.aircraft.state_index import StateIndex
from helireach_ros.core.envelope.domain import ValidityDomain
from helireach_ros.core.resources import data_path, source_root
from helireach_ros.core.units import FT, KT

if TYPE_CHECKING:
    from helireach_ros.core.aircraft.airframe import Airframe
    from helireach_ros.core.ocp.settings import PlannerSettings
    from helireach_ros.core.planning.planner import ControlFunctionWarmStart, WarmStart

__all__ = [
    "DEFAULT_ENVELOPE",
    "FORMAT_NAME",
    "FORMAT_VERSION",
    "FORMAT_VERSION_3D",
    "FORMAT_VERSION_ANSWERS",
    "PENDING",
    "PLAN_STORAGE",
    "QUERY_STATUSES",
    "ROBUST_ARRAYS",
    "ROBUST_CODES",
    "SOLVER_STATE_ARRAYS",
    "SOLVER_STATE_CACHE_ENV",
    "STATUS_CODES",
    "VERDICTS",
    "Envelope",
    "EnvelopeError",
    "EnvelopeQuery",
    "StoredPlan",
    "default_envelope_path",
    "load_envelope",
    "read_envelope_file",
    "save_envelope",
    "settings_differences",
    "solver_state_path",
    "stack_slices",
]

FORMAT_NAME = "helireach-envelope"
FORMAT_VERSION = 1
"""Format version of 2-D files (height × speed), unchanged since the first release."""
FORMAT_VERSION_3D = 2
"""Format version of 3-D files (climb rate × height × speed): ``climb_rates`` and ``boundary_slice`` arrays."""
FORMAT_VERSION_ANSWERS = 3
"""Format version of files written today, 2-D or 3-D (a ``climb_rates`` axis makes it 3-D): the answers and the
plans as initial states and control functions; the solver state only in a partial file."""
_READABLE_VERSIONS: dict[int, bool | None] = {  # version -> holds a climb axis (None: either)
    FORMAT_VERSION: False, FORMAT_VERSION_3D: True, FORMAT_VERSION_ANSWERS: None,
}  # fmt: skip
SOLVER_STATE_ARRAYS = ("plan_primal", "plan_bound_multipliers", "plan_constraint_multipliers")
"""IPOPT's solution per node (float32): in files of versions 1 and 2, in partial files, and in the user cache."""
SOLVER_STATE_CACHE_ENV = "HELIREACH_ENVELOPE_CACHE"
"""Environment variable naming the folder of cached solver states (default: the user cache's
``helireach_ros/envelopes``)."""
DEFAULT_ENVELOPE = "envelopes/uh60a_class_total_power_loss.npz"
"""The shipped envelope, relative to ``data/`` (generated data; ``config/`` holds hand-written input)."""

STATUS_CODES = {"safe": 0, "unsafe": 1, "unverified": 2, "failed": 3, "no_trim": 4}
"""Per-cell status as stored in the file (int8). ``no_trim``: no steady flight at that (speed, climb rate)."""
PENDING = -1
"""Status code of a cell a partial (interrupted) computation has not finished."""
_STATUS_NAMES = {code: name for name, code in STATUS_CODES.items()}
QUERY_STATUSES = (*STATUS_CODES, "not_robust", "outside")
ROBUST_CODES = {"robust": 0, "not_robust": 1, "nominal_not_safe": 2, "not_computed": 3}
"""Per-node robust verdict (int8): ``not_robust`` a model's closed loop failed; ``nominal_not_safe`` not flown
(robust needs nominal safety); ``not_computed`` not flown (e.g. a climb slice other than level flight)."""
ROBUST_ARRAYS = (
    "robust_code", "robust_models_flown", "robust_closed_loop_landed", "robust_open_loop_landed", "robust_seconds",
    "robust_failure_attainable",
)  # fmt: skip
"""The per-node arrays of a robust verdict (all or none)."""
VERDICTS = ("nominal", "robust")
"""What a query answers by: the nominal model's verdict, or the robust one where the envelope has it."""

# Between enclosing nodes of different status, the query reports the most conservative one.
_CONSERVATISM = {"safe": 0, "not_robust": 1, "unverified": 2, "failed": 3, "no_trim": 4, "unsafe": 5}

# Arrays every envelope file holds: name -> (dtype kind, number of leading grid dimensions).
_REQUIRED_ARRAYS = {
    "heights": "f",
    "speeds": "f",
    "status_code": "i",
    "value": "f",
    "time_to_land": "f",
    "replay_value": "f",
    "verified": "b",
    "iterations": "i",
    "solve_time_ms": "f",
    "warm_started": "b",
    "cold_checked": "b",
    "warm_cold_disagree": "b",
    "plan_control_times": "f",
    "plan_control_values": "f",
    "boundary": "f",
    "boundary_unsafe_side": "f",
    "boundary_edge": "i",
}
_CELL_ARRAYS = tuple(name for name in _REQUIRED_ARRAYS if name not in {"heights", "speeds"} and "boundary" not in name)
_INITIAL_STATE = "plan_initial_state"
"""Per node, the state at the failure the plan starts from (6, SI; NaN without a plan): required in version 3."""
_CLIMB_ARRAYS = ("climb_rates", "boundary_slice")
"""The arrays a 3-D file holds beyond the 2-D ones."""
_FPM = FT / 60.0
log = logging.getLogger(__name__)
PLAN_STORAGE = (
    "per node: the state at the failure (plan_initial_state, float64) and the control function (breakpoints and "
    "values, float32); the solver state (NLP primal, bound and constraint multipliers, float32) only in a partial "
    "file, else in the user cache"
)
"""The metadata's ``plan_storage`` text of format version 3."""


class EnvelopeError(ValueError):
    """An envelope file that is missing, corrupt, truncated, partial, or made for something else."""


@dataclass(frozen=True)
class EnvelopeQuery:
    """The envelope's answer for one (height, speed[, climb rate]).

    Attributes:
        status: ``"safe"``, ``"unsafe"``, ``"unverified"``, ``"failed"``, ``"no_trim"`` or ``"outside"``.
        value: the largest optimal value among the enclosing nodes (> 0: unsafe); NaN outside
            the grid or when an enclosing node failed.
        margin: signed distance to the not-proven-safe set in the (ft, kt) plane: > 0 when safe,
            < 0 otherwise; ±inf if there is no such boundary; NaN outside the grid.
        by_interpolation: the enclosing grid nodes disagree (some safe, some not): the point itself is
            neither proven safe nor proven unsafe by the grid.
        verdict: ``"robust"`` when the answer is the robust verdict (every enclosing node has one),
            ``"nominal"`` otherwise (asked for, or the envelope has no robust verdict here).
    """

    status: str
    value: float
    margin: float
    by_interpolation: bool = False
    verdict: str = "nominal"

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready (non-finite numbers become None)."""
        return {
            "status": self.status, "value": _json_number(self.value), "margin": _json_number(self.margin),
            "verdict": self.verdict,
        }  # fmt: skip


@dataclass(frozen=True)
class StoredPlan:
    """The plan stored for one grid node.

    Attributes:
        height: m; ``speed``: m/s (the node's trim state at the failure).
        status: the node's status.
        value: its optimal value.
        time_to_land: s.
        warm_start: for the planner of the envelope's airframe and settings: the NLP solution where the solver
            state is known (:attr:`Envelope.solver_state`), else the control function flown from the node's state.
        control_times, control_values, control_interpolation: the control function
            (see :class:`~helireach_ros.core.ocp.transcription.base.DecodedPlan`).
    """

    height: float
    speed: float
    status: str
    value: float
    time_to_land: float
    warm_start: WarmStart | ControlFunctionWarmStart
    control_times: np.ndarray
    control_values: np.ndarray
    control_interpolation: str
    climb_rate: float = 0.0
    """m/s, positive up: the flight path the node was trimmed on (0 in a 2-D envelope)."""

    def controls_at(self, times) -> np.ndarray:
        """The planned (C_T, θ) at the given times, 2 × len(times) (held constant outside the plan)."""
        from helireach_ros.core.evidence.replay import control_function

        return control_function(self.control_times, self.control_values, self.control_interpolation, times)


def _json_number(value: float) -> float | None:
    return float(value) if math.isfinite(value) else None


def _readonly(array: np.ndarray) -> np.ndarray:
    array = np.array(array, copy=True)
    array.setflags(write=False)
    return array


def _content_checksum(arrays: dict[str, np.ndarray], metadata_json: bytes) -> str:
    digest = hashlib.sha256()
    digest.update(b"metadata\0" + metadata_json)
    for name in sorted(arrays):
        array = np.ascontiguousarray(arrays[name])
        digest.update(f"\0{name}\0{array.dtype.str}\0{array.shape}\0".encode())
        digest.update(array.tobytes())
    return digest.hexdigest()


def _canonical_json(metadata: dict[str, Any]) -> bytes:
    return json.dumps(metadata, sort_keys=True, separators=(",", ":"), allow_nan=False).encode()


def _array_property(name: str, doc: str) -> property:
    return property(lambda self: self._arrays[name], doc=doc)


class Envelope:
    """An immutable H-V envelope, 2-D or 3-D (see the module docstring for the semantics).

    Construct it with :func:`load_envelope` or :mod:`helireach_ros.core.envelope.compute`; the
    constructor validates shapes and codes but not the checksum (that is the file's business).

    Attributes:
        heights: grid heights above ground, m, ascending.
        speeds: grid forward speeds, m/s, ascending.
        climb_rates: grid climb rates, m/s, positive up, ascending (axis 0 of a 3-D envelope); None in a 2-D one.
        status: H × S (3-D: C × H × S) array of ``"safe"``/``"unsafe"``/``"unverified"``/``"failed"``/
            ``"no_trim"`` (``"pending"`` only in a partial envelope).
        value: optimal values, same shape (NaN where the solver failed or there is no trim).
        time_to_land: same shape, s.
        boundary: B × 2 refined boundary points (height m, speed m/s): on each grid line between a
            safe and an unsafe/unverified node, the last point proven safe, within 2 ft / 1 kt
            (by default) of the first point found not safe (3-D: of the slice ``arrays["boundary_slice"]``).
        metadata: a copy of the file's metadata dict.
        envelope_id: a short hash of the content and metadata.
        airframe_name: the airframe's name.
    """

    def __init__(
        self,
        arrays: dict[str, np.ndarray],
        metadata: dict[str, Any],
        solver_state: dict[str, np.ndarray] | None = None,
    ) -> None:
        """``solver_state``: the nodes' IPOPT solutions (:data:`SOLVER_STATE_ARRAYS`) kept beside the arrays (not
        part of the content or its checksum), e.g. from the user cache; ignored when ``arrays`` hold them."""
        missing = sorted(set(_REQUIRED_ARRAYS) - set(arrays))
        if "climb_rates" in arrays:
            missing += [name for name in _CLIMB_ARRAYS if name not in arrays]
        if missing:
            raise EnvelopeError(f"envelope is missing array(s): {', '.join(missing)}")
        self._arrays = {name: _readonly(np.asarray(array)) for name, array in arrays.items()}
        self._metadata_json = _canonical_json(metadata)
        self._metadata = json.loads(self._metadata_json)
        self._validate()
        self._checksum = _content_checksum(self._arrays, self._metadata_json)
        if all(name in self._arrays for name in SOLVER_STATE_ARRAYS):
            solver_state = {name: self._arrays[name] for name in SOLVER_STATE_ARRAYS}
        elif solver_state is not None:
            solver_state = {name: _readonly(np.asarray(solver_state[name])) for name in SOLVER_STATE_ARRAYS}
            self._check_cell_shapes(solver_state)
        self._solver_state = solver_state
        self._status = _readonly(
            np.vectorize(lambda code: _STATUS_NAMES.get(int(code), "pending"), otypes=[object])(
                self._arrays["status_code"]
            ).astype("U10")
        )
        try:
            domain = ValidityDomain.from_metadata(self._metadata)
        except (TypeError, ValueError) as error:
            raise EnvelopeError(f"metadata 'validity_domain' is not valid: {error}") from None
        if self.is_3d:  # the file's own axis is the domain's climb rates, whatever the metadata says
            domain = dataclasses.replace(domain, climb_rates=tuple(float(c) for c in self._arrays["climb_rates"]))
        self._domain = domain
        # every query reads C × H × S arrays: a 2-D envelope is one slice
        self._stacked = {
            name: self._arrays[name] if self.is_3d else self._arrays[name][None]
            for name in ("status_code", "value", "plan_control_times")
        }
        codes = self._stacked["status_code"]
        # the plan's start: the state (version 3) or, in older files, the solver state
        start = self._arrays[_INITIAL_STATE] if _INITIAL_STATE in self._arrays else self._arrays["plan_primal"]
        start = start if self.is_3d else start[None]
        # nodes whose stored plan can warm-start a solve and be flown as a fallback, found once (nearest_plan is
        # on the failure path); a node decided without the NLP (e.g. by a reaction delay) has no plan
        self._usable_plans = (
            (codes >= 0)
            & (codes != STATUS_CODES["failed"])
            & (codes != STATUS_CODES["no_trim"])
            & np.all(np.isfinite(start), axis=3)
            & np.all(np.isfinite(self._stacked["plan_control_times"]), axis=3)
        )
        if start.shape[3] == 0 or self._stacked["plan_control_times"].shape[3] == 0:
            self._usable_plans[:] = False
        self._margin_geometry = self._margins(codes == 0)
        if self.has_robust_verdict:
            robust = self._arrays["robust_code"] if self.is_3d else self._arrays["robust_code"][None]
            self._robust_known = robust != ROBUST_CODES["not_computed"]
            self._robust_margin_geometry = self._margins((codes == 0) & (robust == ROBUST_CODES["robust"]))
            self._stacked["robust_code"] = robust

    def _margins(self, safe: np.ndarray) -> dict[tuple[int, ...], _MarginGeometry]:
        """Margin geometry per enclosing set of slices; between two slices the combined one (safe where both are)."""
        heights_ft, speeds_kt = self.heights / FT, self.speeds / KT
        geometry: dict[tuple[int, ...], _MarginGeometry] = {
            (k,): _MarginGeometry(heights_ft, speeds_kt, safe[k]) for k in range(safe.shape[0])
        }
        geometry.update(
            {
                (k, k + 1): _MarginGeometry(heights_ft, speeds_kt, safe[k] & safe[k + 1])
                for k in range(safe.shape[0] - 1)
            }
        )
        return geometry

    def _validate(self) -> None:
        arrays = self._arrays
        for name, kind in _REQUIRED_ARRAYS.items():
            if arrays[name].dtype.kind != kind and not (kind == "i" and arrays[name].dtype.kind == "u"):
                raise EnvelopeError(f"array {name!r} has dtype {arrays[name].dtype}, expected kind {kind!r}")
        axes = [("heights", arrays["heights"]), ("speeds", arrays["speeds"])]
        if self.is_3d:
            axes.insert(0, ("climb_rates", arrays["climb_rates"]))
        for name, axis in axes:
            minimum = 1 if name == "climb_rates" else 2
            if axis.ndim != 1 or axis.size < minimum or not np.all(np.isfinite(axis)) or np.any(np.diff(axis) <= 0):
                raise EnvelopeError(f"grid axis {name!r} must hold >= {minimum} finite, strictly ascending values")
        self._check_cell_shapes({name: arrays[name] for name in _CELL_ARRAYS})
        version = self._metadata.get("format_version")
        present = [name for name in SOLVER_STATE_ARRAYS if name in arrays]
        if present and len(present) != len(SOLVER_STATE_ARRAYS):
            raise EnvelopeError(f"envelope holds part of the solver state: {', '.join(present)}")
        if version == FORMAT_VERSION_ANSWERS and _INITIAL_STATE not in arrays:
            raise EnvelopeError(f"a format version {version} envelope needs the array {_INITIAL_STATE!r}")
        if version != FORMAT_VERSION_ANSWERS and not present:
            needed = ", ".join(SOLVER_STATE_ARRAYS)
            raise EnvelopeError(f"a format version {version} envelope needs the arrays {needed}")
        optional = [name for name in (*SOLVER_STATE_ARRAYS, _INITIAL_STATE) if name in arrays]
        self._check_cell_shapes({name: arrays[name] for name in optional})
        grid = arrays["status_code"].shape
        codes = arrays["status_code"]
        if not np.all(np.isin(codes, [PENDING, *STATUS_CODES.values()])):
            raise EnvelopeError("status_code holds unknown codes")
        boundary_count = arrays["boundary"].shape[0]
        widths = [("boundary", 2), ("boundary_unsafe_side", 2), ("boundary_edge", 4)]
        for name, width in widths:
            if arrays[name].shape != (boundary_count, width):
                expected = (boundary_count, width)
                raise EnvelopeError(f"array {name!r} has shape {arrays[name].shape}, expected {expected}")
        if self.is_3d:
            slices = arrays["boundary_slice"]
            if slices.shape != (boundary_count,) or slices.dtype.kind not in "iu":
                raise EnvelopeError(f"array 'boundary_slice' must be {boundary_count} integers")
            if boundary_count and not (0 <= slices.min() and slices.max() < grid[0]):
                raise EnvelopeError("array 'boundary_slice' names a climb slice that does not exist")
        present = [name for name in ROBUST_ARRAYS if name in arrays]
        if present:
            if len(present) != len(ROBUST_ARRAYS):
                missing = ", ".join(name for name in ROBUST_ARRAYS if name not in arrays)
                raise EnvelopeError(f"envelope has a robust verdict without array(s): {missing}")
            for name in ROBUST_ARRAYS:
                if arrays[name].shape != codes.shape:
                    raise EnvelopeError(f"array {name!r} has shape {arrays[name].shape}, expected {codes.shape}")
            if not np.all(np.isin(arrays["robust_code"], list(ROBUST_CODES.values()))):
                raise EnvelopeError("robust_code holds unknown codes")
            robust = arrays["robust_code"] == ROBUST_CODES["robust"]
            if np.any(robust & (codes != STATUS_CODES["safe"])):
                raise EnvelopeError("robust_code calls a node robust that is not safe")
        if self._metadata.get("format") != FORMAT_NAME:
            raise EnvelopeError(f"metadata format is {self._metadata.get('format')!r}, expected {FORMAT_NAME!r}")

    def _check_cell_shapes(self, arrays: dict[str, np.ndarray]) -> None:
        """Per-node arrays lead with the grid's shape (C × H × S or H × S)."""
        axes = ("climb_rates", "heights", "speeds") if self.is_3d else ("heights", "speeds")
        grid = tuple(self._arrays[axis].size for axis in axes)
        for name, array in arrays.items():
            if array.shape[: len(grid)] != grid:
                raise EnvelopeError(f"array {name!r} has shape {array.shape}, expected {grid} leading")

    # --- the contract's attributes -------------------------------------------------------------
    heights = _array_property("heights", "Grid heights above ground, m, ascending.")
    speeds = _array_property("speeds", "Grid forward speeds, m/s, ascending.")
    value = _array_property("value", "Optimal values, H × S (3-D: C × H × S); NaN where the solver failed.")
    time_to_land = _array_property("time_to_land", "Landing times of the stored plans, s, shaped like ``value``.")
    boundary = _array_property("boundary", "B × 2 refined boundary points (height m, speed m/s), the safe side.")

    @property
    def is_3d(self) -> bool:
        """The envelope has a climb-rate axis (format version 2)."""
        return "climb_rates" in self._arrays

    @property
    def format_version(self) -> int:
        """The file format version the content follows (:data:`FORMAT_VERSION_ANSWERS` for files written today)."""
        version = self._metadata.get("format_version", FORMAT_VERSION)
        return version if type(version) is int else 0  # 0: not a version (the file reader refuses such a file)

    @property
    def solver_state(self) -> dict[str, np.ndarray] | None:
        """The nodes' IPOPT solutions (:data:`SOLVER_STATE_ARRAYS`, read-only) where known: in the file (versions
        1 and 2, partial files) or from the user cache; None otherwise (stored plans then warm-start from their
        control functions)."""
        return None if self._solver_state is None else dict(self._solver_state)

    def answers(self) -> Envelope:
        """This envelope as today's file holds it (format version 3): no solver state in the content, the control
        functions in float32, the initial states in float64; the solver state, if known, rides along
        (:attr:`solver_state`).

        Raises:
            EnvelopeError: an envelope of an older version (no initial states to rebuild its plans from).
        """
        if _INITIAL_STATE not in self._arrays:
            raise EnvelopeError(
                f"a format version {self.format_version} envelope has no plan initial states; recompute it with "
                "'helireach envelope compute' to write today's format"
            )
        arrays = {name: array for name, array in self._arrays.items() if name not in SOLVER_STATE_ARRAYS}
        for name in ("plan_control_times", "plan_control_values"):
            arrays[name] = arrays[name].astype(np.float32)
        arrays[_INITIAL_STATE] = arrays[_INITIAL_STATE].astype(np.float64)
        metadata = dict(self._metadata, format_version=FORMAT_VERSION_ANSWERS, plan_storage=PLAN_STORAGE)
        return Envelope(arrays, metadata, self._solver_state)

    @property
    def has_robust_verdict(self) -> bool:
        """The envelope holds robust verdicts (:data:`ROBUST_ARRAYS`; they may cover only some nodes)."""
        return "robust_code" in self._arrays

    @property
    def robust_status(self) -> np.ndarray | None:
        """Per-node robust verdict names (:data:`ROBUST_CODES`), shaped like ``status``; None without them."""
        if not self.has_robust_verdict:
            return None
        names = {code: name for name, code in ROBUST_CODES.items()}
        return np.vectorize(names.__getitem__, otypes=[object])(self._arrays["robust_code"]).astype("U16")

    @property
    def climb_rates(self) -> np.ndarray | None:
        """Climb rates of the slices, m/s, positive up, ascending; None for a 2-D (level-trim) envelope."""
        return self._arrays["climb_rates"] if self.is_3d else None

    @property
    def _slice_climb_rates(self) -> np.ndarray:
        """The climb rate of every slice, m/s: a 2-D envelope's one slice is level flight."""
        return self._arrays["climb_rates"] if self.is_3d else np.zeros(1)

    @property
    def validity_domain(self) -> ValidityDomain:
        """Where the envelope's answers hold (its climb rates are the file's climb axis in a 3-D envelope)."""
        return self._domain

    @property
    def status(self) -> np.ndarray:
        return self._status

    @property
    def metadata(self) -> dict[str, Any]:
        return copy.deepcopy(self._metadata)

    @property
    def envelope_id(self) -> str:
        return self._checksum[:16]

    @property
    def checksum(self) -> str:
        """The full SHA-256 content checksum (as stored in the file)."""
        return self._checksum

    @property
    def airframe_name(self) -> str:
        return str(self._metadata.get("airframe", {}).get("name", "unknown"))

    @property
    def conditions(self) -> str:
        """The conditions the envelope holds for: ``W = 16000 lbf, density altitude 0 ft, calm``."""
        return _describe_conditions(self._metadata.get("airframe", {}))

    @property
    def rotor_model_text(self) -> str:
        """The rotor model the envelope was computed with, in words ("paper rotor" when the airframe record has
        none: the paper's rotor, or a file from before the rotor model existed; and for the ``paper`` method, whose
        planner flies the airframe's paper reproduction whatever the file's rotor)."""
        rotor = self._metadata.get("airframe", {}).get("rotor_model")
        if not rotor or self._metadata.get("settings", {}).get("method") == "paper":
            return "paper rotor"
        return f"{rotor.get('inflow', '?')} rotor" + (", ground effect" if rotor.get("ground_effect") else "")

    # --- further read-only views ---------------------------------------------------------------
    @property
    def power_fraction(self) -> float:
        """Engine power left after the failure, as a fraction of trim power (0 = total loss)."""
        return float(self._metadata["power_fraction"])

    @property
    def complete(self) -> bool:
        """False for a partial file left by an interrupted computation."""
        return bool(self._metadata.get("complete", False)) and not np.any(self._arrays["status_code"] == PENDING)

    @property
    def arrays(self) -> dict[str, np.ndarray]:
        """Every stored array (read-only views), e.g. ``verified``, ``iterations``, ``cold_checked``."""
        return dict(self._arrays)

    # --- climb slices --------------------------------------------------------------------------
    def nearest_slice(self, climb_rate: float) -> int:
        """Index of the climb slice nearest to ``climb_rate`` (m/s; 0 for a 2-D envelope).

        Raises:
            ValueError: a climb rate that is not a finite number.
        """
        climb_rate = _as_float(climb_rate)
        if not math.isfinite(climb_rate):
            raise ValueError(f"climb rate must be a finite number, got {climb_rate!r}")
        return int(np.argmin(np.abs(self._slice_climb_rates - climb_rate)))

    def slice(self, index: int) -> Envelope:
        """The 2-D envelope of one climb slice (a 2-D envelope returns itself).

        Its metadata gains ``climb_slice`` (index, climb rate in m/s and ft/min) and a validity domain at that
        climb rate ± the level tolerance; its boundary points are the slice's own.
        """
        if not self.is_3d:
            return self
        count = self._slice_climb_rates.size
        if not -count <= index < count:
            raise IndexError(f"climb slice {index} of an envelope with {count}")
        index %= count
        climb_rate = float(self._slice_climb_rates[index])
        arrays = {
            name: array if _is_axis_or_boundary(name) else array[index]  # every other array is per node
            for name, array in self._arrays.items()
            if name not in _CLIMB_ARRAYS
        }
        in_slice = self._arrays["boundary_slice"] == index
        for name in ("boundary", "boundary_unsafe_side", "boundary_edge"):
            arrays[name] = self._arrays[name][in_slice]
        metadata = copy.deepcopy(self._metadata)
        metadata["format_version"] = FORMAT_VERSION_ANSWERS if self.format_version == FORMAT_VERSION_ANSWERS else (
            FORMAT_VERSION)  # fmt: skip
        metadata["climb_slice"] = {
            "index": index, "climb_rate_m_s": climb_rate, "climb_rate_fpm": climb_rate / _FPM, "of": count,
        }  # fmt: skip
        metadata["validity_domain"] = dataclasses.replace(self._domain, climb_rates=(climb_rate,)).to_metadata()
        solver_state = None
        if self._solver_state is not None and not all(name in arrays for name in SOLVER_STATE_ARRAYS):
            solver_state = {name: array[index] for name, array in self._solver_state.items()}
        return Envelope(arrays, metadata, solver_state)

    # --- queries -------------------------------------------------------------------------------
    def _enclosing_slices(self, climb_rate: float) -> list[int] | None:
        """Climb slices enclosing ``climb_rate`` (1 or 2), None outside the domain's climb-rate range."""
        low, high = self._domain.climb_rate_range()
        if not (math.isfinite(climb_rate) and low <= climb_rate <= high):
            return None
        if self._stacked["status_code"].shape[0] == 1:
            return [0]  # one slice: it speaks for its tolerance band
        return _enclosing_nodes(self._slice_climb_rates, climb_rate)

    def query(
        self, height_m: float, speed_ms: float, climb_rate: float = 0.0, verdict: str = "nominal"
    ) -> EnvelopeQuery:
        """Status, value and margin at a trimmed state (see the module docstring).

        Args:
            height_m: height above ground, m.
            speed_ms: forward speed, m/s.
            climb_rate: m/s, positive up (default level flight). Outside the envelope's climb-rate range
                (a 2-D envelope: level ± its tolerance) the answer is ``outside``.
            verdict: ``"nominal"``, or ``"robust"``: the robust verdict where every enclosing node has one
                (a safe node that is not robust is ``not_robust``), else the nominal one; the answer's
                ``verdict`` says which it is.

        Anything that is not a finite number (NaN, inf, None, text) is ``outside``.

        Raises:
            ValueError: an unknown ``verdict``.
        """
        if verdict not in VERDICTS:
            raise ValueError(f"verdict must be one of {', '.join(VERDICTS)}, got {verdict!r}")
        height_m, speed_ms, climb_rate = _as_float(height_m), _as_float(speed_ms), _as_float(climb_rate)
        rows = _enclosing_nodes(self.heights, height_m)
        columns = _enclosing_nodes(self.speeds, speed_ms)
        slices = self._enclosing_slices(climb_rate)
        if rows is None or columns is None or slices is None:
            return EnvelopeQuery("outside", math.nan, math.nan)
        enclosing = np.ix_(slices, rows, columns)
        codes = self._stacked["status_code"][enclosing].ravel()
        names = [_STATUS_NAMES.get(int(code), "failed") for code in codes]  # a pending node counts as failed
        geometry = self._margin_geometry
        robust = verdict == "robust" and self.has_robust_verdict and bool(np.all(self._robust_known[enclosing]))
        if robust:
            robust_codes = self._stacked["robust_code"][enclosing].ravel()
            names = [
                "not_robust" if name == "safe" and code != ROBUST_CODES["robust"] else name
                for name, code in zip(names, robust_codes, strict=True)
            ]
            geometry = self._robust_margin_geometry
        status = max(names, key=_CONSERVATISM.__getitem__)
        value = float(np.max(self._stacked["value"][enclosing]))
        margin = geometry[tuple(slices)].margin(height_m / FT, speed_ms / KT, status == "safe")
        return EnvelopeQuery(
            status, value, margin, "safe" in names and len(set(names)) > 1, "robust" if robust else "nominal"
        )

    def status_at(self, height_m: float, speed_ms: float, climb_rate: float = 0.0, verdict: str = "nominal") -> str:
        """Shortcut for ``query(height_m, speed_ms, climb_rate, verdict).status``."""
        return self.query(height_m, speed_ms, climb_rate, verdict).status

    def margin(self, height_m: float, speed_ms: float, climb_rate: float = 0.0) -> float:
        """Shortcut for ``query(height_m, speed_ms, climb_rate).margin`` (ft/kt units)."""
        return self.query(height_m, speed_ms, climb_rate).margin

    def nearest_plan(self, height_m: float, speed_ms: float, climb_rate: float = 0.0) -> StoredPlan | None:
        """The stored plan of the nearest node whose solve converged (a warm start, never a safety claim).

        Nearest in (ft, kt) — in a 3-D envelope in (climb rate, ft, kt) with the climb rate in kt
        (1 kt ≈ 101 ft/min: the same velocity unit as the speed axis). A non-finite climb rate counts as
        level flight. Returns None for a non-finite height or speed, or when no node has a usable plan.
        """
        height_m, speed_ms, climb_rate = _as_float(height_m), _as_float(speed_ms), _as_float(climb_rate)
        if not (math.isfinite(height_m) and math.isfinite(speed_ms)):
            return None
        usable = self._usable_plans
        if not np.any(usable):
            return None
        climbs = self._slice_climb_rates
        climb_rate = climb_rate if math.isfinite(climb_rate) else 0.0
        distance = np.sqrt(
            ((climbs[:, None, None] - climb_rate) / KT) ** 2
            + ((self.heights[None, :, None] - height_m) / FT) ** 2
            + ((self.speeds[None, None, :] - speed_ms) / KT) ** 2
        )
        distance[~usable] = np.inf
        index, row, column = np.unravel_index(int(np.argmin(distance)), distance.shape)
        return self.stored_plan(int(row), int(column), int(index))

    def nearest_plan_to(self, state: np.ndarray) -> StoredPlan | None:
        """:meth:`nearest_plan` for a model state (y, v, Ω, h, z, P; SI): its height, speed and climb rate −y."""
        state = np.asarray(state, dtype=float).reshape(-1)
        height, speed = state[StateIndex.HEIGHT], state[StateIndex.FORWARD_SPEED]
        return self.nearest_plan(height, speed, -state[StateIndex.DESCENT_RATE])

    def has_stored_plan(self, row: int, column: int, climb_index: int = 0) -> bool:
        """Whether node (row, column) [of climb slice ``climb_index``] stores a plan that can warm-start a solve and
        be flown (what :meth:`nearest_plan` offers; not a node that failed or was decided without the NLP)."""
        return bool(self._usable_plans[climb_index if self.is_3d else 0, row, column])

    def stored_plan(self, row: int, column: int, climb_index: int = 0) -> StoredPlan:
        """The plan stored at grid node (row, column) [of climb slice ``climb_index``], as float64."""
        from helireach_ros.core.planning.planner import ControlFunctionWarmStart, WarmStart

        node = (climb_index, row, column) if self.is_3d else (row, column)
        arrays = self._arrays
        control_times = arrays["plan_control_times"][node].astype(float)
        control_values = arrays["plan_control_values"][node].astype(float)
        solver_state = self._solver_state
        warm_start: WarmStart | ControlFunctionWarmStart
        if solver_state is not None and np.all(np.isfinite(solver_state["plan_primal"][node])):
            warm_start = WarmStart(*(solver_state[name][node].astype(float) for name in SOLVER_STATE_ARRAYS))
        else:
            warm_start = ControlFunctionWarmStart(
                arrays[_INITIAL_STATE][node].astype(float),
                control_times,
                control_values,
                float(self._metadata.get("settings", {}).get("reaction_delay_s", 0.0)),
            )
        return StoredPlan(
            height=float(self.heights[row]),
            speed=float(self.speeds[column]),
            status=str(self.status[node]),
            value=float(self.value[node]),
            time_to_land=float(self.time_to_land[node]),
            warm_start=warm_start,
            control_times=control_times,
            control_values=control_values,
            control_interpolation=str(self._metadata.get("control_interpolation", "zero_order_hold")),
            climb_rate=float(self._slice_climb_rates[climb_index]),
        )

    def check_matches(
        self,
        airframe: Airframe | None = None,
        settings: PlannerSettings | None = None,
        power_fraction: float | None = None,
        where: str = "envelope",
    ) -> None:
        """Raises :class:`EnvelopeError` unless the envelope was made for these (None: not checked)."""
        metadata = self._metadata
        if airframe is not None:
            stored = metadata.get("airframe", {})
            if stored.get("digest") != airframe.digest():
                raise EnvelopeError(
                    f"{where} was computed for airframe {stored.get('name')!r} (digest {stored.get('digest')}, "
                    f"{_describe_conditions(stored)}), not for {airframe.name!r} (digest {airframe.digest()}, "
                    f"{_describe_conditions(airframe.as_dict())}); compute an envelope for it with "
                    f"'helireach envelope compute'"
                )
        if settings is not None:
            differences = settings_differences(metadata.get("settings", {}), settings)
            if differences:
                raise EnvelopeError(f"{where} was computed with other planner settings: {'; '.join(differences)}")
        if power_fraction is not None and not math.isclose(
            float(metadata.get("power_fraction", math.nan)), float(power_fraction), rel_tol=0.0, abs_tol=1e-9
        ):
            raise EnvelopeError(f"{where} is for power fraction {metadata.get('power_fraction')}, not {power_fraction}")

    def __repr__(self) -> str:
        counts = {name: int(np.sum(self.status == name)) for name in STATUS_CODES}
        climbs = f"{self._slice_climb_rates.size}x" if self.is_3d else ""
        return (
            f"Envelope({self.airframe_name}, {climbs}{self.heights.size}x{self.speeds.size}, power_fraction="
            f"{self.power_fraction:g}, {counts}, id={self.envelope_id})"
        )


def _is_axis_or_boundary(name: str) -> bool:
    return name in {"heights", "speeds", *_CLIMB_ARRAYS} or name.startswith("boundary")


def stack_slices(slices: Sequence[Envelope], climb_rates: Sequence[float], metadata: dict[str, Any]) -> Envelope:
    """The 3-D envelope of 2-D slices on one height × speed grid, one per climb rate (the inverse of ``slice``).

    Args:
        slices: 2-D envelopes with the same axes and the same arrays (plans of one size).
        climb_rates: m/s, ascending, one per slice.
        metadata: the 3-D envelope's metadata (``control_interpolation`` is taken from the slices).

    Raises:
        EnvelopeError: slices on different grids, or a count that does not match ``climb_rates``.
    """
    if not slices or len(slices) != len(climb_rates):
        raise EnvelopeError(f"{len(slices)} slices for {len(climb_rates)} climb rates")
    first = slices[0].arrays
    for other in slices[1:]:
        arrays = other.arrays
        if set(arrays) != set(first) or any(
            not np.array_equal(arrays[axis], first[axis]) for axis in ("heights", "speeds")
        ):
            raise EnvelopeError("climb slices must share their grid and arrays")
    stacked: dict[str, np.ndarray] = {"climb_rates": np.asarray(climb_rates, float)}
    for name in first:
        if name in {"heights", "speeds"}:
            stacked[name] = first[name]
        elif name.startswith("boundary"):
            stacked[name] = np.concatenate([envelope.arrays[name] for envelope in slices])
        else:
            stacked[name] = np.stack([envelope.arrays[name] for envelope in slices])
    stacked["boundary_slice"] = np.concatenate(
        [np.full(envelope.boundary.shape[0], index, np.int16) for index, envelope in enumerate(slices)]
    )
    interpolation = next((e.metadata.get("control_interpolation") for e in slices if e.metadata.get(
        "control_interpolation")), "")  # fmt: skip
    return Envelope(stacked, dict(metadata, control_interpolation=interpolation))


def settings_differences(stored: dict[str, Any], settings: PlannerSettings) -> list[str]:
    """The fields where stored settings (a dict) and ``settings`` differ, as ``name: stored != given``.

    A field the stored settings predate counts as its default: a setting is added with the behaviour before it as
    its default, so a file computed before it exists was computed with that default.
    """
    from helireach_ros.core.ocp.settings import PlannerSettings

    given, defaults = dataclasses.asdict(settings), dataclasses.asdict(PlannerSettings())
    return [
        f"{name}: {stored.get(name, defaults.get(name))!r} != {given.get(name)!r}"
        for name in sorted(set(stored) | set(given))
        if stored.get(name, defaults.get(name)) != given.get(name)
    ]


def _describe_conditions(airframe: dict[str, Any]) -> str:
    try:
        from helireach_ros.core.units import KT, LBF

        wind = float(airframe.get("headwind", 0.0))  # absent: calm (a calm airframe's digest leaves it out)
        return (
            f"W = {float(airframe['gross_weight']) / LBF:.0f} lbf, "
            f"density altitude {float(airframe['density_altitude']) / FT:.0f} ft, "
            + (f"headwind {wind / KT:+.0f} kt" if wind else "calm")
        )
    except (KeyError, TypeError, ValueError):
        return "conditions unknown"


def _as_float(value: Any) -> float:
    try:
        return float(value)
    except (TypeError, ValueError):
        return math.nan


def _enclosing_nodes(axis: np.ndarray, x: float, tolerance: float = 1e-9) -> list[int] | None:
    """Indices of the grid nodes enclosing x along one axis (1 on a node, 2 between), None outside."""
    if not math.isfinite(x):
        return None
    scale = tolerance * max(1.0, float(axis[-1] - axis[0]))
    if x < axis[0] - scale or x > axis[-1] + scale:
        return None
    index = int(np.clip(np.searchsorted(axis, x, side="right") - 1, 0, axis.size - 2))
    fraction = (x - axis[index]) / (axis[index + 1] - axis[index])
    if fraction <= tolerance:
        return [index]
    if fraction >= 1.0 - tolerance:
        return [index + 1]
    return [index, index + 1]


class _MarginGeometry:
    """Rectangles (in ft, kt) whose union is the closure of the not-proven-safe set, and of the safe set.

    Under the node rule, the not-proven-safe set is the union of the grid cells with a non-safe
    corner (each closed cell); the safe set's closure is the union of all-safe cells, edges with
    two safe ends, and safe nodes. A margin is the distance to the other set.
    """

    def __init__(self, heights_ft: np.ndarray, speeds_kt: np.ndarray, safe: np.ndarray) -> None:
        corners_safe = safe[:-1, :-1] & safe[1:, :-1] & safe[:-1, 1:] & safe[1:, 1:]
        rows, columns = np.meshgrid(np.arange(heights_ft.size - 1), np.arange(speeds_kt.size - 1), indexing="ij")

        def cells(mask):
            r, c = rows[mask], columns[mask]
            return np.stack([heights_ft[r], heights_ft[r + 1], speeds_kt[c], speeds_kt[c + 1]], axis=1)

        self.unsafe_rectangles = cells(~corners_safe)
        vertical = safe[:-1, :] & safe[1:, :]  # edges along heights
        horizontal = safe[:, :-1] & safe[:, 1:]  # edges along speeds
        r, c = np.nonzero(vertical)
        vertical_edges = np.stack([heights_ft[r], heights_ft[r + 1], speeds_kt[c], speeds_kt[c]], axis=1)
        r, c = np.nonzero(horizontal)
        horizontal_edges = np.stack([heights_ft[r], heights_ft[r], speeds_kt[c], speeds_kt[c + 1]], axis=1)
        r, c = np.nonzero(safe)
        nodes = np.stack([heights_ft[r], heights_ft[r], speeds_kt[c], speeds_kt[c]], axis=1)
        self.safe_rectangles = np.concatenate([cells(corners_safe), vertical_edges, horizontal_edges, nodes])

    @staticmethod
    def _distance(rectangles: np.ndarray, height_ft: float, speed_kt: float) -> float:
        if rectangles.shape[0] == 0:
            return math.inf
        dy = np.maximum(np.maximum(rectangles[:, 0] - height_ft, height_ft - rectangles[:, 1]), 0.0)
        dx = np.maximum(np.maximum(rectangles[:, 2] - speed_kt, speed_kt - rectangles[:, 3]), 0.0)
        return float(np.min(np.hypot(dx, dy)))

    def margin(self, height_ft: float, speed_kt: float, safe: bool) -> float:
        if safe:
            return self._distance(self.unsafe_rectangles, height_ft, speed_kt)
        return -self._distance(self.safe_rectangles, height_ft, speed_kt)


def solver_state_path(checksum: str) -> Path:
    """Where the solver state of the envelope with this content checksum is cached (see the module docstring)."""
    folder = os.environ.get(SOLVER_STATE_CACHE_ENV)
    if not folder:
        base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
        folder = os.path.join(base, "helireach_ros", "envelopes")
    return Path(folder) / f"solver_state_{checksum[:32]}.npz"


def save_envelope(envelope: Envelope, path: str | os.PathLike[str]) -> Path:
    """Writes an envelope atomically (temporary file + rename) with its checksum.

    A complete envelope of today's format is written without its solver state, which goes to the user cache
    (:func:`solver_state_path`; a cache that cannot be written only costs warm-start speed). A partial one keeps
    it in the file, for ``--resume``; an older format is written as it is.

    Returns:
        The path written.
    """
    if envelope.complete and envelope.format_version == FORMAT_VERSION_ANSWERS:
        envelope = envelope.answers()
        cached = solver_state_path(envelope.checksum)
        if envelope.solver_state is not None and _cached_solver_state(envelope.checksum) is None:
            try:  # the same checksum is the same content: a valid cache file is not written again
                _write_npz(cached, _solver_state_payload(envelope))
            except OSError as error:
                log.warning("could not cache the envelope's solver state in %s: %s", cached, error)
    arrays = envelope.arrays
    payload = {name: np.ascontiguousarray(array) for name, array in arrays.items()}
    payload["metadata_json"] = np.frombuffer(envelope._metadata_json, dtype=np.uint8)
    payload["checksum"] = np.frombuffer(envelope.checksum.encode(), dtype=np.uint8)
    return _write_npz(Path(path), payload)


def _solver_state_payload(envelope: Envelope) -> dict[str, np.ndarray]:
    """The solver-state cache file's arrays: the state, the answers' checksum, and a checksum over both."""
    state = {name: np.ascontiguousarray(array) for name, array in (envelope.solver_state or {}).items()}
    owner = envelope.checksum.encode()
    return state | {
        "answers_checksum": np.frombuffer(owner, dtype=np.uint8),
        "checksum": np.frombuffer(_content_checksum(state, owner).encode(), dtype=np.uint8),
    }


def _cached_solver_state(checksum: str) -> dict[str, np.ndarray] | None:
    """The cached solver state of the envelope with this checksum, None if absent, unreadable or not its own."""
    path = solver_state_path(checksum)
    if not path.is_file():
        return None
    try:
        with np.load(path, allow_pickle=False) as archive:
            contents = {name: archive[name] for name in archive.files}
        owner = contents.pop("answers_checksum").tobytes()
        stored = contents.pop("checksum").tobytes().decode("ascii")
    except Exception as error:  # a cache file is a convenience: anything wrong with it means "not cached"
        log.warning("ignoring the cached solver state %s: %s: %s", path, type(error).__name__, error)
        return None
    if (
        owner != checksum.encode()
        or _content_checksum(contents, owner) != stored
        or set(contents) != set(SOLVER_STATE_ARRAYS)
    ):
        log.warning("ignoring the cached solver state %s: it is not this envelope's, or it is corrupt", path)
        return None
    return contents


def _write_npz(target: Path, payload: dict[str, np.ndarray]) -> Path:
    target.parent.mkdir(parents=True, exist_ok=True)
    temporary = target.with_name(f".{target.name}.{os.getpid()}.tmp")
    try:
        with open(temporary, "wb") as handle:
            np.savez_compressed(handle, **payload)  # type: ignore[arg-type]  # numpy's stub types **kwds as its flag
            handle.flush()
            os.fsync(handle.fileno())
        os.replace(temporary, target)
    finally:
        temporary.unlink(missing_ok=True)
    return target


def read_envelope_file(path: str | os.PathLike[str], allow_partial: bool = False) -> Envelope:
    """Reads and checks an envelope file (checksum, format, shapes) without matching it to anything.

    Args:
        path: the ``.npz`` file.
        allow_partial: accept a partial file from an interrupted computation (for ``--resume``).

    Raises:
        EnvelopeError: missing, unreadable, truncated, corrupt, of another format, or partial.
    """
    source = Path(path)
    try:
        raw = source.read_bytes()
    except OSError as error:
        raise EnvelopeError(f"envelope file {str(source)!r}: cannot read: {error.strerror or error}") from None
    try:
        with np.load(io.BytesIO(raw), allow_pickle=False) as archive:
            contents = {name: archive[name] for name in archive.files}
    except Exception as error:  # a corrupt archive can fail anywhere in zipfile/numpy's parsers
        raise EnvelopeError(
            f"envelope file {str(source)!r} is truncated or corrupt (not a readable .npz archive): "
            f"{type(error).__name__}: {error}"
        ) from None
    try:
        metadata_json = contents.pop("metadata_json").tobytes()
        stored_checksum = contents.pop("checksum").tobytes().decode("ascii")
        metadata = json.loads(metadata_json)
    except (KeyError, UnicodeDecodeError, json.JSONDecodeError) as error:
        raise EnvelopeError(f"envelope file {str(source)!r} has no valid metadata/checksum: {error}") from None
    if _content_checksum(contents, metadata_json) != stored_checksum:
        raise EnvelopeError(f"envelope file {str(source)!r} is corrupt: its content does not match its checksum")
    if not isinstance(metadata, dict) or metadata.get("format") != FORMAT_NAME:
        raise EnvelopeError(f"{str(source)!r} is not a {FORMAT_NAME} file")
    version = metadata.get("format_version")
    if not isinstance(version, int) or version not in _READABLE_VERSIONS:
        raise EnvelopeError(
            f"envelope file {str(source)!r} has format version {version}, this software reads versions "
            f"{', '.join(str(v) for v in _READABLE_VERSIONS)}; recompute it"
        )
    if _READABLE_VERSIONS[version] not in (None, "climb_rates" in contents):
        kind = "3-D" if _READABLE_VERSIONS[version] else "2-D"
        raise EnvelopeError(
            f"envelope file {str(source)!r} is a format version {version} ({kind}) file without "
            f"the matching climb-rate axis"
        )
    solver_state = None
    if not all(name in contents for name in SOLVER_STATE_ARRAYS):
        solver_state = _cached_solver_state(stored_checksum)
    try:
        envelope = Envelope(contents, metadata, solver_state)
    except EnvelopeError as error:
        if solver_state is None:
            raise EnvelopeError(f"envelope file {str(source)!r}: {error}") from None
        log.warning("ignoring the cached solver state of %s: %s", source, error)
        envelope = Envelope(contents, metadata)
    if not allow_partial and not envelope.complete:
        done = int(np.sum(envelope.arrays["status_code"] != PENDING))
        raise EnvelopeError(
            f"envelope file {str(source)!r} is a partial result of an interrupted computation ({done} of "
            f"{envelope.status.size} nodes solved, not all checked and refined); finish it with "
            f"'helireach envelope compute ... --resume'"
        )
    return envelope


def load_envelope(
    path: str | os.PathLike[str],
    airframe: Airframe | None = None,
    settings: PlannerSettings | None = None,
    power_fraction: float | None = None,
) -> Envelope:
    """Loads a complete envelope and checks that it was made for the given airframe/settings/power.

    Args:
        path: the ``.npz`` file.
        airframe: if given, must equal the envelope's airframe (by digest).
        settings: if given, must equal the envelope's planner settings (every field).
        power_fraction: if given, must equal the envelope's power fraction.

    Raises:
        EnvelopeError: naming the file, for a missing/corrupt/truncated/partial file or a mismatch.
    """
    envelope = read_envelope_file(path)
    envelope.check_matches(airframe, settings, power_fraction, where=f"envelope file {str(path)!r}")
    return envelope


def default_envelope_path() -> Path:
    """The shipped ``uh60a_class`` total-power-loss envelope (installed share or source tree)."""
    try:
        return data_path(DEFAULT_ENVELOPE)
    except FileNotFoundError:
        return source_root() / "data" / DEFAULT_ENVELOPE
