"""``make demo``: the 500 ft / 75 kt engine failure of the paper, planned, verified and drawn.

(The ROS system's full demo replaces this first version.)
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

__all__ = ["main"]


def main(argv: list[str] | None = None) -> int:
    """Plans the paper's example landing and writes its figure; exits 0 only if it is safe."""
    parser = argparse.ArgumentParser(prog="helireach-demo", description=__doc__)
    parser.add_argument("--out", default="out", help="folder for the figure")
    arguments = parser.parse_args(argv)
    from helireach_ros.plan_cli import run_plan

    figure = Path(arguments.out) / "landing_500ft_75kt.png"
    plan_arguments = argparse.Namespace(
        airframe="uh60a_class", height_ft=500.0, speed_kt=75.0, power_fraction=0.0, method=None, settings=None,
        weight_lb=None, density_altitude_ft=None, json=False, plot=str(figure),
    )  # fmt: skip
    return run_plan(plan_arguments)


if __name__ == "__main__":
    sys.exit(main())
