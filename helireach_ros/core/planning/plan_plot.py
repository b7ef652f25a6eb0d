"""Figure of a landing plan: the paper's Fig. 3 (states against time) plus the independent replay.

Collocation nodes are dots, the collocation polynomial a solid line, the replay of the plan's
controls through the model a dashed line; the controls are drawn as the function the replay used.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from helireach_ros.core.aircraft.state_index import StateIndex
from helireach_ros.core.planning.planner import LandingPlan
from helireach_ros.core.units import FT, KT

__all__ = ["plot_landing_plan"]

# (state index, label, factor from SI to the plotted unit)
_STATE_PANELS = (
    (3, "height above ground [ft]", 1.0 / FT),
    (0, "descent rate [ft/s]", 1.0 / FT),
    (2, "rotor speed [% of nominal]", None),
    (1, "forward speed [kt]", 1.0 / KT),
)


def plot_landing_plan(plan: LandingPlan, out_path: str | Path, title: str | None = None) -> Path:
    """Writes the plan's figure (PNG or any format matplotlib infers from the suffix).

    Args:
        plan: the landing plan.
        out_path: where to write the figure.
        title: optional title; by default the initial height/speed and the plan's status.

    Returns:
        The path written.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figure, axes = plt.subplots(3, 2, figsize=(11, 10), sharex=True)
    panels = axes.reshape(-1)
    replay = plan.replay
    for panel, (index, label, factor) in zip(panels, _STATE_PANELS, strict=False):
        scale = factor if factor is not None else 100.0 / plan.nominal_rotor_speed
        panel.plot(
            plan.curve_times, plan.curve_states[index] * scale, "-", color="tab:blue", lw=1.4, label="collocation"
        )
        panel.plot(plan.times, plan.states[index] * scale, ".", color="tab:red", ms=5, label="nodes")
        panel.plot(replay.times, replay.states[index] * scale, "--", color="black", lw=1.1, label="replay (CVODES)")
        panel.set_ylabel(label)
        panel.grid(alpha=0.3)
    panels[0].legend(loc="upper right", fontsize=8)

    dense_times = np.linspace(0.0, plan.time_to_land, 600)
    controls = plan.controls_at(dense_times)
    node_controls = plan.controls_at(plan.times)
    panels[4].plot(dense_times, controls[0], "-", color="tab:green", lw=1.4)
    panels[4].plot(plan.times, node_controls[0], ".", color="tab:red", ms=5)
    panels[4].set_ylabel("thrust coefficient C_T")
    panels[5].plot(dense_times, np.degrees(controls[1]), "-", color="tab:purple", lw=1.4)
    panels[5].plot(plan.times, np.degrees(node_controls[1]), ".", color="tab:red", ms=5)
    panels[5].set_ylabel("pitch angle θ [deg, + nose down]")
    for panel in panels[4:]:
        panel.set_xlabel("time since failure [s]")
        panel.grid(alpha=0.3)

    if title is None:
        height_ft = plan.initial_state[StateIndex.HEIGHT] / FT
        speed_kt = plan.initial_state[StateIndex.FORWARD_SPEED] / KT
        touchdown = replay.touchdown_state
        title = (
            f"{height_ft:.0f} ft, {speed_kt:.0f} kt — {plan.status.upper()} ({plan.method}), "
            f"lands in {plan.time_to_land:.2f} s; replay touchdown {touchdown[0] / FT:.1f} ft/s, "
            f"{touchdown[1] / KT:.1f} kt"
        )
    figure.suptitle(title)
    figure.tight_layout()
    path = Path(out_path)
    path.parent.mkdir(parents=True, exist_ok=True)
    figure.savefig(path, dpi=110)
    plt.close(figure)
    return path
