"""``helireach nlp-cache``: compile the landing NLP's functions and the block LDL^T into the user cache.

What ``make nlp-cache`` runs: for each airframe (default ``uh60a_class``) with the planner settings file, the NLP's
CasADi functions are generated as C, compiled and stored under their checksum
(:mod:`helireach_ros.core.ocp.compiled_nlp`), and so is IPOPT's linear solver (:mod:`helireach_ros.core.ocp.block_ldl`).
Later planners of the same NLP load them; without them the planner runs the plain functions, never an error.
``--objective`` adds the NLPs of other objectives (repeatable): ``site`` for a planner node with landing sites,
``nearest_touchdown`` and ``farthest_touchdown`` for its live footprint (each ~3.5 min on 2 cores, once).
Exit codes: 0 built (or already there), 2 bad input (an unknown airframe or objective, or a broken settings file).
"""

from __future__ import annotations

import argparse
import dataclasses
import sys

__all__ = ["main", "register"]


def _build(arguments: argparse.Namespace) -> int:
    from helireach_ros.core.aircraft.airframe import ConfigError, load_airframe
    from helireach_ros.core.ocp.compiled_nlp import CodegenSettings
    from helireach_ros.core.ocp.settings import load_settings
    from helireach_ros.core.planning.planner import LandingPlanner

    codegen = dataclasses.replace(CodegenSettings.from_environment(), mode="build")
    try:
        settings = load_settings(arguments.settings)
        airframes = [load_airframe(name) for name in arguments.airframe or ["uh60a_class"]]
        variants = [settings, *(settings.replace(objective=objective) for objective in arguments.objective or ())]
    except (ConfigError, FileNotFoundError, ValueError) as error:
        print(f"helireach nlp-cache: {error}", file=sys.stderr)
        return 2
    for airframe in airframes:
        for variant in variants:
            planner = LandingPlanner(airframe, variant, codegen)
            functions, solver = planner.nlp_functions, planner.linear_solver
            print(f"{airframe.name} ({variant.objective}): {functions}; linear solver {solver}")
    return 0


def _add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--airframe", action="append", help="airframe name (repeatable; default uh60a_class)")
    parser.add_argument("--settings", help="planner settings file (default config/planner.yaml)")
    parser.add_argument(
        "--objective",
        action="append",
        help="also the NLP of this objective (repeatable): site, nearest_touchdown, farthest_touchdown",
    )
    parser.set_defaults(handler=_build)


def register(subparsers: argparse._SubParsersAction) -> None:
    """Adds ``nlp-cache``."""
    parser = subparsers.add_parser(
        "nlp-cache", help="compile the NLP functions and the linear solver into the user cache (make nlp-cache)"
    )
    _add_arguments(parser)


def main(argv: list[str] | None = None) -> int:
    """``python -m helireach_ros.cli.nlp_cache`` (the same as ``helireach nlp-cache``)."""
    parser = argparse.ArgumentParser(prog="helireach nlp-cache", description=__doc__.splitlines()[0])
    _add_arguments(parser)
    arguments = parser.parse_args(argv)
    return arguments.handler(arguments)


if __name__ == "__main__":
    raise SystemExit(main())
