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
off-site"), never "unsafe" for a state that can land.
"""

from __future__ import annotations

import math
import threading
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from helireach_ros.core.aircraft.state_index import StateIndex

if TYPE_CHECKING:
    from helireach_ros.core.planning.planner import LandingPlan

__all__ = [
    "LandingSite",
    "SiteSelection",
    "parse_landing_sites",
    "site_values",
    "solve_site_or_anywhere",
]


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


class SiteSelection:
    """Which site a failure now would land on (see the module docstring). Thread-safe: the live evaluations record
    from the solver's threads, the failure reads on its own.

    Args:
        sites: the sites, in the crew's order of preference.
        selected: the crew's choice ('' = automatic).

    Raises:
        ValueError: ``selected`` names no site of the list.
    """

    def __init__(self, sites: Sequence[LandingSite], selected: str = "") -> None:
        self.sites = tuple(sites)
        if selected and selected not in {site.name for site in self.sites}:
            raise ValueError(f"selected_site {selected!r} is not one of the landing sites")
        self.crew_choice = selected
        self._lock = threading.Lock()
        self._reachable: dict[str, bool] = {}  # the latest evidence per site name
        self._current = 0

    def selected(self) -> LandingSite | None:
        """The site a failure now would land on (None: no sites)."""
        if not self.sites:
            return None
        if self.crew_choice:
            return next(site for site in self.sites if site.name == self.crew_choice)
        with self._lock:
            return self.sites[self._current]

    def record(self, site: LandingSite, reachable: bool) -> None:
        """The latest evidence about ``site``: a plan for it landed on it (``reachable``), or it did not. An
        automatic selection moves on to the next site after its site was not reached."""
        with self._lock:
            self._reachable[site.name] = reachable
            if not reachable and not self.crew_choice and self.sites[self._current] == site:
                self._current = (self._current + 1) % len(self.sites)

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
            self._reachable.clear()
            self._current = 0


def solve_site_or_anywhere(
    solve_site: Callable[[np.ndarray, Any], LandingPlan],
    solve_anywhere: Callable[[np.ndarray, Any], LandingPlan],
    state: np.ndarray,
    warm_start: Any,
) -> LandingPlan:
    """The landing on the site if one is verified, else the landing anywhere if that is safe, else the site's
    attempt (its status says why). Each ``solve(state, warm_start)`` is one planner's (site, and touchdown-cost),
    with any cold check of its own; the anywhere solve is cold (the site's warm point pins it to the site)."""
    on_site = solve_site(state, warm_start)
    if on_site.safe:
        return on_site
    anywhere = solve_anywhere(state, None)
    return anywhere if anywhere.safe else on_site


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
