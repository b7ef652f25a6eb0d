"""Command-line options that several ``helireach`` subcommands share."""

from __future__ import annotations

import argparse

from helireach_ros.core.aircraft.airframe import ROTOR_MODEL_CHOICES

__all__ = ["add_rotor_model_option"]


def add_rotor_model_option(parser: argparse.ArgumentParser) -> None:
    """``--rotor-model airframe|paper|momentum``, for
    :meth:`~helireach_ros.core.aircraft.airframe.Airframe.with_rotor_model_choice`."""
    parser.add_argument(
        "--rotor-model",
        choices=ROTOR_MODEL_CHOICES,
        default="airframe",
        help="rotor aerodynamics: the airframe file's, the paper's hover inflow, or momentum inflow with ground "
        "effect (default: %(default)s; the paper method always uses the paper's)",
    )
