"""Landing sites along the track, which one a failure lands on, and what a plan says about it; no ROS.

A **landing site** is an interval of the track, in the same along-track distance as the vehicle's odometry
(``pose.position.x``, the model's z): a field, a clearing, a runway. A plan for it is the planner's ``site`` objective
with the touchdown window the site's ends minus the state's z (:meth:`LandingSite.window_from`), safe only when its
independent replay touches down inside the site.

The **selection** (:class:`SiteSelection`): the crew's site (parameter ``selected_site``) whenever one is named;
otherwise the first site of the list that the latest evidence does not call unreachable — the selection stays on a
site while its plans land on it, and moves on to the next site of the list after a live plan could not reach it
(so that, with several sites, the standby plan is for a site that was reachable at the latest evaluation).

**Site, then anywhere** (:func:`solve_site_or_anywhere`): a state from which the selected site cannot be reached
may still land off-site. The planner then lands anywhere, and the status says both ("site X not reachable; landing
off-site"), never "unsafe" for a state that can land. A site attempt that cannot succeed is the expensive case (IPOPT
runs to ``site_max_iterations``: ~0.3-0.6 s), so after a solve found the site not reachable the next solves go
straight to anywhere and try the site again only every :data:`SITE_RETRY_EVERY`-th time
(:meth:`SiteSelection.worth_trying`): the live rate and the re-plans keep their pace, and a site that comes back
within reach is found again within a few solves.

**The live footprint** (:func:`footprint_report`): the nearest and farthest replay-verified touchdowns from the latest
measured state (:mod:`~helireach_ros.core.planning.footprint`), and what they say of each site: beyond a verified end
it is not reachable; between two verified ends it overlaps what the aircraft can reach (a site plan decides).
"""

from __future__ import annotations

import math
import threading
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from helireach_ros.core.aircraft.state_index import StateIndex
from helireach_ros.core.planning.footprint import ReachableFootprint, SiteReachability
from helireach_ros.core.policies.live_reachability import solve_with_cold_check
from helireach_ros.core.policies.plan_status import StatusReport

if TYPE_CHECKING:
    from helireach_ros.core.planning.planner import LandingPlan

__all__ = [
    "SITE_RETRY_EVERY",
    "LandingSite",
    "SiteSelection",
    "footprint_off_reason",
    "footprint_off_report",
    "footprint_report",
    "parse_landing_sites",
    "parse_site_list",
    "plan_site_or_anywhere",
    "site_list_text",
    "site_values",
    "sites_from_message",
    "sites_report",
    "solve_site_or_anywhere",
]


SITE_RETRY_EVERY = 5
"""After a solve found a site not reachable, every this-many-th solve tries it again (the others land anywhere at
once); at the live rate (5 Hz) a site that comes back within reach is found within a second (assumed)."""


@dataclass(frozen=True)
class LandingSite:
    """A landing site: an interval of the track.

    Attributes:
        name: what the crew calls it (unique in a list).
        start_m: its near end, m of along-track distance (the odometry's ``position.x``).
        end_m: its far end, m (≥ ``start_m``).
    """

    name: str
    start_m: float
    end_m: float

    def __post_init__(self) -> None:
        if not self.name or ":" in self.name:
            raise ValueError(f"a landing site needs a name without ':', got {self.name!r}")
        if not (math.isfinite(self.start_m) and math.isfinite(self.end_m) and self.start_m <= self.end_m):
            ends = f"{self.start_m}..{self.end_m}"
            raise ValueError(f"landing site {self.name!r}: start <= end, both finite (m), got {ends}")

    def window_from(self, state: np.ndarray) -> tuple[float, float]:
        """The site as a touchdown window from ``state`` (m of touchdown distance along the track)."""
        here = float(np.asarray(state, dtype=float)[StateIndex.DISTANCE])
        return self.start_m - here, self.end_m - here

    def contains(self, distance_m: float) -> bool:
        """Whether an along-track distance (m) lies on the site."""
        return self.start_m <= distance_m <= self.end_m

    def margin_m(self, distance_m: float) -> float:
        """How far inside the site's nearer end a distance lies, m (negative outside)."""
        return min(distance_m - self.start_m, self.end_m - distance_m)


def parse_landing_sites(entries: Sequence[str]) -> tuple[LandingSite, ...]:
    """Sites from ``"name:start_m:end_m"`` strings (the planner parameter ``landing_sites``).

    Raises:
        ValueError: a malformed entry, non-finite or reversed ends, or a name used twice.
    """
    sites: list[LandingSite] = []
    for entry in entries:
        parts = [part.strip() for part in str(entry).split(":")]
        if len(parts) != 3:
            raise ValueError(f"a landing site is 'name:start_m:end_m', got {entry!r}")
        try:
            start, end = float(parts[1]), float(parts[2])
        except ValueError:
            raise ValueError(f"a landing site's ends are numbers (m), got {entry!r}") from None
        sites.append(LandingSite(parts[0], start, end))
    names = [site.name for site in sites]
    repeated = sorted({name for name in names if names.count(name) > 1})
    if repeated:
        raise ValueError(f"landing site names must be unique, repeated: {', '.join(repeated)}")
    return tuple(sites)


def parse_site_list(text: str) -> tuple[LandingSite, ...]:
    """Sites from one string, ``"name:start_m:end_m;name:start_m:end_m"`` (the planner parameter ``landing_sites``
    and the ``landing_sites`` value of a mission manager's message); empty entries are ignored.

    Raises:
        ValueError: as :func:`parse_landing_sites`.
    """
    return parse_landing_sites([entry for entry in str(text).split(";") if entry.strip()])


def site_list_text(sites: Sequence[LandingSite]) -> str:
    """The sites as :func:`parse_site_list` reads them."""
    return ";".join(f"{site.name}:{site.start_m:g}:{site.end_m:g}" for site in sites)


def sites_from_message(values: Mapping[str, str]) -> tuple[tuple[LandingSite, ...], str]:
    """The sites and the crew's choice a mission manager sends (msg_docs/mission_landing_sites.md): the values
    ``landing_sites`` (as the parameter) and ``selected_site`` ('' or absent = automatic).

    Raises:
        ValueError: no ``landing_sites`` value, or one :func:`parse_site_list` refuses.
    """
    if "landing_sites" not in values:
        raise ValueError("a landing-sites message needs a 'landing_sites' value ('name:start_m:end_m;...')")
    return parse_site_list(values["landing_sites"]), str(values.get("selected_site", "")).strip()


def sites_report(selection: SiteSelection | None, reason: str = "") -> StatusReport:
    """The planner's landing sites as it uses them (``/helireach/landing_sites``, latched): OK with sites, WARN
    without (the planner lands anywhere; ``reason`` says why, e.g. a refused list)."""
    if selection is None or not selection.sites:
        why = reason or "no landing sites configured"
        source = selection.source if selection is not None else "parameter"
        values = {"landing_sites": "", "selected_site": "", "site_count": 0, "source": source, "reason": why}
        return StatusReport("WARN", f"landing sites: none ({why}): landing anywhere", values)
    sites, crew = selection.sites, selection.crew_choice
    selected = selection.selected()
    values = {
        "landing_sites": site_list_text(sites),
        "selected_site": crew,
        "selection": selected.name if selected is not None else "",
        "site_count": len(sites),
        "source": selection.source,
        "reason": reason,
    }
    listed = ", ".join(f"{site.name} {site.start_m:.0f}-{site.end_m:.0f} m" for site in sites)
    choice = f"the crew's {crew}" if crew else "automatic"
    refused = f" ({reason})" if reason else ""
    text = f"landing sites from the {selection.source}: {listed}; selected: {choice}{refused}"
    return StatusReport("OK", text, values)


class SiteSelection:
    """Which site a failure now would land on (see the module docstring). Thread-safe: the live evaluations record
    from the solver's threads, the failure reads on its own.

    Args:
        sites: the sites, in the crew's order of preference.
        selected: the crew's choice ('' = automatic).

    Raises:
        ValueError: ``selected`` names no site of the list.
    """

    def __init__(self, sites: Sequence[LandingSite], selected: str = "", source: str = "parameter") -> None:
        self._lock = threading.Lock()
        self._reachable: dict[str, bool] = {}  # the latest evidence per site name
        self._skipped: dict[str, int] = {}  # solves that went straight to anywhere since the site was not reachable
        self._current = 0
        self._sites: tuple[LandingSite, ...] = ()
        self._crew_choice = ""
        self.source = source
        self.replace(sites, selected, source)

    def replace(self, sites: Sequence[LandingSite], selected: str = "", source: str = "topic") -> None:
        """New sites and crew choice (e.g. from a mission manager's topic); the evidence about the old ones is dropped.

        Raises:
            ValueError: ``selected`` names no site of the list (nothing is changed).
        """
        sites = tuple(sites)
        if selected and selected not in {site.name for site in sites}:
            raise ValueError(f"selected_site {selected!r} is not one of the landing sites")
        with self._lock:  # one step: no reader sees the new sites with the old selection index
            self._sites, self._crew_choice, self.source = sites, selected, source
            self._clear_evidence()

    @property
    def sites(self) -> tuple[LandingSite, ...]:
        """The sites, in the crew's order of preference."""
        with self._lock:
            return self._sites

    @property
    def crew_choice(self) -> str:
        """The crew's site by name ('' = automatic)."""
        with self._lock:
            return self._crew_choice

    def selected(self) -> LandingSite | None:
        """The site a failure now would land on (None: no sites)."""
        with self._lock:
            if not self._sites:
                return None
            if self._crew_choice:
                return next(site for site in self._sites if site.name == self._crew_choice)
            return self._sites[self._current]

    def record(self, site: LandingSite, reachable: bool) -> None:
        """The latest evidence about ``site``: a plan for it landed on it (``reachable``), or it did not. An
        automatic selection moves on to the next site after its site was not reached."""
        with self._lock:
            self._reachable[site.name] = reachable
            self._skipped.pop(site.name, None)
            current = self._sites[self._current] if self._sites else None
            if not reachable and not self._crew_choice and current == site:
                self._current = (self._current + 1) % len(self._sites)

    def worth_trying(self, site: LandingSite) -> bool:
        """Whether a solve now should try ``site``: yes unless the latest evidence says it is not reachable, and then
        every :data:`SITE_RETRY_EVERY`-th time (a call that answers no counts as a solve that skipped it)."""
        with self._lock:
            if self._reachable.get(site.name) is not False:
                return True
            skipped = self._skipped.get(site.name, 0) + 1
            self._skipped[site.name] = 0 if skipped >= SITE_RETRY_EVERY else skipped
            return skipped >= SITE_RETRY_EVERY

    def reachable_count(self) -> int:
        """Sites whose latest plan landed on them."""
        with self._lock:
            return sum(self._reachable.values())

    def reachability(self, site: LandingSite) -> bool | None:
        """The latest evidence about one site (None: none yet)."""
        with self._lock:
            return self._reachable.get(site.name)

    def forget(self) -> None:
        """Drops the evidence (a reset; the automatic selection starts again at the first site)."""
        with self._lock:
            self._clear_evidence()

    def _clear_evidence(self) -> None:  # under the lock
        self._reachable.clear()
        self._skipped.clear()
        self._current = 0


def solve_site_or_anywhere(
    solve_site: Callable[[np.ndarray, Any], LandingPlan],
    solve_anywhere: Callable[[np.ndarray, Any], LandingPlan],
    state: np.ndarray,
    warm_start: Any,
) -> LandingPlan:
    """The landing on the site if one is verified, else the landing anywhere if that is safe, else the best effort:
    of the two plans that converged, the one with the lower value (a failed site attempt must not hide a converged
    plan anywhere: the node would publish a fallback instead), the site's attempt if neither did. Each
    ``solve(state, warm_start)`` is one planner's (site, and touchdown-cost), with any cold check of its own; the
    anywhere solve is cold (the site's warm point pins it to the site)."""
    on_site = solve_site(state, warm_start)
    if on_site.safe:
        return on_site
    anywhere = solve_anywhere(state, None)
    if anywhere.safe:
        return anywhere
    converged = [plan for plan in (on_site, anywhere) if plan.solver.success and not math.isnan(plan.value)]
    return min(converged, key=lambda plan: plan.value) if converged else on_site


def plan_site_or_anywhere(
    anywhere_planner: Any,
    site_planner: Any | None,
    state: np.ndarray,
    warm_start: Any,
    window: tuple[float, float] | None,
    *,
    cold_check: bool,
    **request: Any,
) -> LandingPlan:
    """One solve as the planner node makes it, in a worker or in its own process: on the site (``window``, m from
    the state) if a plan for it is verified, else anywhere (:func:`solve_site_or_anywhere`); without a window,
    anywhere. Warm starts cross between the two NLPs (``carried_warm_start``); ``request`` goes to every ``plan``.

    ``cold_check`` (live evaluations) applies to the anywhere solve only: the verdict must not call a state unsafe
    that a cold start would land, but a site missed by a warm start is only a landing elsewhere, tried again by a
    later solve, while a cold re-solve of a site beyond reach costs its whole iteration limit a second time.
    """

    def solver(planner: Any, **extra: Any) -> Callable[[np.ndarray, Any], LandingPlan]:
        def solve(at: np.ndarray, warm: Any) -> LandingPlan:
            return planner.plan(at, planner.carried_warm_start(warm), **request, **extra)

        return solve

    anywhere = solver(anywhere_planner)
    if cold_check:
        plain = anywhere

        def anywhere(at: np.ndarray, warm: Any) -> LandingPlan:
            return solve_with_cold_check(plain, at, warm)

    if window is None or site_planner is None:
        return anywhere(state, warm_start)
    return solve_site_or_anywhere(solver(site_planner, touchdown_window=window), anywhere, state, warm_start)


def site_values(
    site: LandingSite | None, plan: LandingPlan | None, reachable_count: int | None = None
) -> dict[str, Any]:
    """The site keys of a plan or live status (msg_docs/helireach_plan_status.md): the site aimed at, where the plan
    touches down (world m, the replay's), whether that is on the site, and the margin to its nearer end."""
    if site is None:
        return {}
    values: dict[str, Any] = {"landing_site": site.name, "site_start_m": site.start_m, "site_end_m": site.end_m}
    if reachable_count is not None:
        values["sites_reachable"] = reachable_count
    if plan is None:
        return values
    touchdown = float(plan.replay.touchdown_state[StateIndex.DISTANCE])
    aimed = plan.touchdown_window is not None
    values.update(
        touchdown_distance_m=touchdown,
        site_planned=aimed,
        on_site=bool(aimed and plan.safe and site.contains(touchdown)),
        site_margin_m=site.margin_m(touchdown) if math.isfinite(touchdown) else math.nan,
    )
    return values


def footprint_report(
    nearest: LandingPlan | None,
    farthest: LandingPlan | None,
    *,
    state: np.ndarray,
    stamp_ns: int,
    solve_time_ms: float,
    sites: SiteSelection | None,
    reason: str = "",
) -> StatusReport:
    """The live footprint's status (msg_docs/helireach_reachable_footprint.md): OK with both ends verified, WARN
    with one, ERROR with none (unknown, not "no landing": the live verdict answers that).

    Args:
        nearest, farthest: the two ends' plans (None: no answer); only a safe (replay-verified) end counts.
        state: the state they were solved from (y, v, Ω, h, z, P).
        stamp_ns: its stamp.
        solve_time_ms: wall time of both ends, ms.
        sites: the landing sites (each gets its reachability as far as the footprint tells).
        reason: why an end has no answer.
    """
    here = float(state[StateIndex.DISTANCE])
    footprint = ReachableFootprint(
        nearest if nearest is not None and nearest.safe else None,
        farthest if farthest is not None and farthest.safe else None,
        (),
    )
    verified = (footprint.nearest is not None) + (footprint.farthest is not None)
    status = {2: "reachable", 1: "partial", 0: "unknown"}[verified]
    values: dict[str, Any] = {
        "status": status,
        "nearest_m": footprint.nearest_m,
        "farthest_m": footprint.farthest_m,
        "nearest_distance_m": here + footprint.nearest_m,
        "farthest_distance_m": here + footprint.farthest_m,
        "nearest_verified": footprint.nearest is not None,
        "farthest_verified": footprint.farthest is not None,
        "state_stamp_ns": stamp_ns,
        "distance_m": here,
        "height_m": float(state[StateIndex.HEIGHT]),
        "forward_speed_m_s": float(state[StateIndex.FORWARD_SPEED]),
        "solve_time_ms": solve_time_ms,
        "reason": reason,
    }
    reachability = {
        site.name: footprint.site_reachability(*site.window_from(state)) for site in (sites.sites if sites else ())
    }
    values.update({f"site_{name}": answer.value for name, answer in reachability.items()})
    if sites is not None:
        values["sites_in_footprint"] = sum(answer is SiteReachability.REACHABLE for answer in reachability.values())
    answers = [f"{name} {answer.value.replace('_', ' ')}" for name, answer in reachability.items()]
    ends = f"{footprint.nearest_m:.0f}-{footprint.farthest_m:.0f} m ahead"
    listed = f"; sites: {', '.join(answers)}" if answers else ""
    if verified == 2:
        return StatusReport("OK", f"footprint: touchdown {ends} (both ends verified){listed}", values)
    if verified == 1:
        return StatusReport("WARN", f"footprint: one end verified ({ends}; NaN = unknown){listed}", values)
    why = f" ({reason})" if reason else ""
    return StatusReport("ERROR", f"footprint: UNKNOWN, no end verified{why}{listed}", values)


def footprint_off_reason(*, period_s: float, live: bool, pool: bool, method: str) -> str:
    """Why the planner node solves no live footprint ('' = it does): it needs a period, the live evaluations (it
    takes their slots), a solver pool and the flyable method."""
    if period_s <= 0.0:
        return "footprint_period is 0"
    if not live:
        return "live evaluation is off (live_rate 0)"
    if not pool:
        return "no solver pool (solver_workers 0)"
    if method != "flyable":
        return f"the {method} method has no footprint (flyable only)"
    return ""


def footprint_off_report(reason: str) -> StatusReport:
    """STALE: no live footprint, and why (published once, latched)."""
    return StatusReport("STALE", f"footprint: OFF ({reason})", {"status": "off", "reason": reason})
