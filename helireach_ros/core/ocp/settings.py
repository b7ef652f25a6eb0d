"""Planner settings: which transcription, its resolution, IPOPT options and replay tolerances."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml

from helireach_ros.core.aircraft.airframe import ConfigError
from helireach_ros.core.resources import config_path

__all__ = ["FOOTPRINT_OBJECTIVES", "METHODS", "OBJECTIVES", "PlannerSettings", "load_settings"]

METHODS = ("flyable", "verified", "paper")
OBJECTIVES = ("terminal", "reach_avoid", "nearest_touchdown", "farthest_touchdown", "site")
"""What the flyable NLP minimises (:attr:`PlannerSettings.objective`)."""
FOOTPRINT_OBJECTIVES = ("nearest_touchdown", "farthest_touchdown")
"""The objectives of the reachable footprint's two ends (:mod:`~helireach_ros.core.planning.footprint`)."""


@dataclass(frozen=True)
class PlannerSettings:
    """How a landing NLP is transcribed and solved. Immutable and hashable: solvers are cached on it.

    Attributes:
        method: ``"flyable"`` (the default: the verified mesh with continuous, rate-limited controls, the
            airframe's attitude and touchdown-attitude limits, touchdown on the ground and no climbing once
            below the commit height; :mod:`helireach_ros.core.ocp.transcription.flyable`), ``"verified"``
            (free-final-time multi-interval Radau in physical time, piecewise-constant controls, the paper's
            limits) or ``"paper"`` (the paper's single-interval LGR with time freeze and log time transform).
        intervals: verified: number of collocation intervals.
        degree: verified: Radau IIA points per interval.
        final_interval_ratio: verified: length of the last interval over the first; < 1 puts more
            intervals into the flare, where the paper's scheme loses its accuracy.
        min_time_to_land: verified: lower bound on the landing time, s.
        max_time_to_land: verified: upper bound on the landing time, s.
        smoothness_weight: weight of the control-smoothness term that makes the plan unique among
            equally safe ones (the secondary criterion); it can only raise the value, never lower it.
        paper_points: paper: N, the number of LGR collocation points.
        paper_time_scale: paper: c in s = c log(2 / (1 − τ)), s.
        tolerance: IPOPT ``tol``.
        max_iterations: IPOPT ``max_iter``.
        warm_start_bound_push: warm-started solves only: IPOPT ``warm_start_bound_push`` and
            ``warm_start_mult_bound_push`` (how far the start point and its bound multipliers are moved
            off the bounds). A neighbour's solution is already interior; a small push keeps it (measured:
            8 instead of 10 iterations, the same classification).
        warm_bound_push: warm-started solves only: IPOPT ``bound_push`` and ``bound_frac``. Cold solves keep
            IPOPT's defaults (0.01): these small values slow them down.
        replay_relative_tolerance: CVODES relative tolerance of the independent replay.
        replay_samples_per_interval: replay output points per control interval.
        rotor_speed_backoff: the NLP keeps Ω this fraction of Ω₀ inside its limits at the collocation
            points, because between points the true trajectory can overshoot them (measured: up to
            0.6 % of Ω₀); the replay then checks the true limits.
        rotor_speed_replay_margin: tolerance of the replay's rotor-speed check, fraction of Ω₀
            (default 0: the true limits).
        reaction_delay_s: s after the failure during which the controls stay at their pre-failure values
            (the pilot's or the automation's reaction time) before the plan takes over; the plan carries this
            segment and the replay flies it. 0 = the plan starts at the failure.
        objective: flyable: ``"terminal"``, the paper's touchdown cost J = max(|y|/y_max, |v|/v_max) − 1 with every
            path limit a hard constraint; or ``"reach_avoid"``, the reach-avoid value: the largest of J and the
            normalised margins of the rotor-speed limits along the path and of the touchdown attitude (each 0 at its
            limit, −1 the airframe's ``margin_scales`` inside it; :mod:`~helireach_ros.core.ocp.transcription.flyable`),
            so a plan keeps its worst margin as large as it can instead of riding the limits. The limits stay hard
            constraints either way, so the same states are safe (value ≤ 0). ``"nearest_touchdown"`` and
            ``"farthest_touchdown"``: the touchdown distance z(T) minimised or maximised subject to a safe touchdown
            (J ≤ −``footprint_margin`` a constraint): the ends of the reachable footprint. ``"site"``: the touchdown
            cost with the touchdown distance held inside a landing site given per solve
            (:meth:`~helireach_ros.core.planning.planner.LandingPlanner.plan`'s ``touchdown_window``). Other methods:
            always ``"terminal"``.
        footprint_margin: how far inside the touchdown limits a footprint end lands (J ≤ −margin; 0.05 = 5 % of
            the nearest touchdown limit, the live status's caution threshold, so that an end is never a landing the
            status would call marginal; assumed). The end at J = 0 exactly would ride the limit.
        site_backoff_m: how far inside a landing site's ends the NLP holds its touchdown, m (the replay judges the
            site's true ends: 3 m covers the replayed touchdown's drift from the NLP's, 0.6 m at 500 ft / 75 kt;
            assumed).
        site_max_iterations: IPOPT's iteration limit for a site plan (the ``site`` objective), at most
            ``max_iterations``. IPOPT does not find a site beyond the aircraft's reach infeasible: it runs to its limit
            (measured, ``bench/site_latency.py``: 300 iterations, ~2 s per attempt, on the site NLP's plain CasADi
            functions), and the planner then lands anywhere; a reachable site's plan took 17-21 iterations warm and
            35-37 cold on average. 100 bounds the attempt to about a third of that (assumed; a plan that needs more
            is answered off-site, never unsafe).
        wind_touchdown_min_descent_rate: with wind (the airframe's ``headwind`` not 0), the plan touches down at no
            less than this descent rate, m/s (0.3 ≈ 1 ft/s; assumed). Into wind the touchdown cost can reach its floor,
            J = −1, at zero ground speed and zero descent rate: the plan then grazes the ground, and the replay's
            contact, whose time a centimetre of height moves by tens of milliseconds at a near-zero descent rate,
            comes with the flare attitude outside the touchdown window (measured from 500 ft / 75 kt into 15 kt:
            J = −1.000, replayed touchdown attitude 14.8° nose-up against 12°, UNVERIFIED; with this bound J = −0.877,
            1.0 ft/s and 1.8 kt replayed, SAFE). Calm NLPs are unchanged (the shipped envelopes are calm).
        closed_form_states: verified and flyable: the distance z and the engine power P are not decision
            variables but their collocation solutions in closed form (z the quadrature of v, P the solution
            of Ṗ = −P/τ), which satisfy their collocation equations exactly; neither feeds back into the
            other states except P into Ω̇. The NLP has 4 instead of 6 states per point (282 instead of 402
            variables for the flyable default) and no degenerate P ≥ 0 bound when P = 0. False: the NLP with all
            six (as before, for comparisons).
    """

    method: str = "flyable"
    intervals: int = 20
    degree: int = 3
    final_interval_ratio: float = 0.35
    min_time_to_land: float = 0.2
    max_time_to_land: float = 60.0
    smoothness_weight: float = 1e-3
    paper_points: int = 24
    paper_time_scale: float = 3.0
    tolerance: float = 1e-7
    max_iterations: int = 300
    warm_start_bound_push: float = 1e-9
    warm_bound_push: float = 1e-8
    replay_relative_tolerance: float = 1e-8
    replay_samples_per_interval: int = 8
    rotor_speed_backoff: float = 0.01
    rotor_speed_replay_margin: float = 0.0
    reaction_delay_s: float = 0.0
    closed_form_states: bool = True
    objective: str = "terminal"
    footprint_margin: float = 0.05
    site_backoff_m: float = 3.0
    site_max_iterations: int = 100
    wind_touchdown_min_descent_rate: float = 0.3

    @property
    def iteration_limit(self) -> int:
        """IPOPT's ``max_iter`` for this NLP: ``max_iterations``, or ``site_max_iterations`` for a site plan."""
        return min(self.max_iterations, self.site_max_iterations) if self.objective == "site" else self.max_iterations

    def __post_init__(self) -> None:
        problems = []
        if self.method not in METHODS:
            problems.append(f"method must be one of {METHODS}, got {self.method!r}")
        if self.objective not in OBJECTIVES:
            problems.append(f"objective must be one of {OBJECTIVES}, got {self.objective!r}")
        elif (self.objective in FOOTPRINT_OBJECTIVES or self.objective == "site") and self.method != "flyable":
            problems.append(f"objective {self.objective!r} needs the flyable method, got {self.method!r}")
        integer_ranges: tuple[tuple[str, int, int], ...] = (
            ("intervals", 1, 1000),
            ("degree", 1, 9),
            ("paper_points", 3, 200),
            ("max_iterations", 1, 100000),
            ("site_max_iterations", 1, 100000),
            ("replay_samples_per_interval", 1, 1000),
        )
        for name, low, high in integer_ranges:
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or not low <= value <= high:
                problems.append(f"{name} must be an integer in [{low}, {high}], got {value!r}")
        real_ranges: tuple[tuple[str, float, float], ...] = (
            ("final_interval_ratio", 0.01, 100.0),
            ("min_time_to_land", 0.01, 10.0),
            ("max_time_to_land", 1.0, 600.0),
            ("smoothness_weight", 0.0, 1.0),
            ("paper_time_scale", 0.1, 100.0),
            ("tolerance", 1e-12, 1e-2),
            ("warm_start_bound_push", 1e-12, 0.5),
            ("warm_bound_push", 1e-12, 0.5),
            ("replay_relative_tolerance", 1e-12, 1e-3),
            ("rotor_speed_backoff", 0.0, 0.1),
            ("rotor_speed_replay_margin", 0.0, 0.1),
            ("reaction_delay_s", 0.0, 10.0),
            ("footprint_margin", 0.0, 0.5),
            ("site_backoff_m", 0.0, 100.0),
            ("wind_touchdown_min_descent_rate", 0.0, 5.0),
        )
        for name, real_low, real_high in real_ranges:
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int | float) or not real_low <= value <= real_high:
                problems.append(f"{name} must be a number in [{real_low:g}, {real_high:g}], got {value!r}")
        if not isinstance(self.closed_form_states, bool):
            problems.append(f"closed_form_states must be true or false, got {self.closed_form_states!r}")
        if not problems and self.min_time_to_land >= self.max_time_to_land:
            problems.append("min_time_to_land must be below max_time_to_land")
        if problems:
            raise ConfigError("planner settings: " + "; ".join(problems))

    def replace(self, **changes: Any) -> PlannerSettings:
        """A copy with some fields changed (validated again)."""
        return dataclasses.replace(self, **changes)


def load_settings(path: str | Path | None = None, **overrides: Any) -> PlannerSettings:
    """Loads planner settings from YAML (default ``config/planner.yaml``), then applies overrides.

    Raises:
        ConfigError: unknown keys, wrong types, or values out of range (the message names them).
    """
    source = config_path(path if path is not None else "planner.yaml")
    try:
        document = yaml.safe_load(source.read_text()) or {}
    except (OSError, yaml.YAMLError) as error:
        raise ConfigError(f"{source}: cannot read planner settings: {error}") from None
    if not isinstance(document, dict):
        raise ConfigError(f"{source}: planner settings must be a mapping")
    known = {field.name for field in dataclasses.fields(PlannerSettings)}
    unknown = sorted(set(document) - known)
    if unknown:
        raise ConfigError(f"{source}: unknown planner setting(s): {', '.join(unknown)}")
    document.update({key: value for key, value in overrides.items() if value is not None})
    try:
        return PlannerSettings(**document)
    except ConfigError as error:
        raise ConfigError(f"{source}: {error}") from None
