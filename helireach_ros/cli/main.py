"""The ``helireach`` command: one entry point, subcommands contributed by the modules that own them.

Each module in :data:`SUBCOMMAND_MODULES` has ``register(subparsers)``, which adds its subcommand
with ``set_defaults(handler=...)``; a handler takes the parsed arguments and returns an exit code, by one
convention (docs/guides/using.md, "Exit codes"): 0 success (for a safety answer: safe), 1 a valid request
answered "no" (not safe) or not produced, 2 bad input with one line on stderr (argparse's own usage errors are 2
as well).
Modules keep heavy imports (CasADi, rclpy) inside their handlers so ``helireach --help`` is fast.
"""

from __future__ import annotations

import argparse
import importlib
import sys

from helireach_ros import __version__

__all__ = ["SUBCOMMAND_MODULES", "build_parser", "main"]

SUBCOMMAND_MODULES = (
    "helireach_ros.cli.plan",
    "helireach_ros.cli.envelope",
    "helireach_ros.cli.bringup",
    "helireach_ros.cli.replay",
    "helireach_ros.cli.log",
    "helireach_ros.cli.display",
    "helireach_ros.cli.demo",
    "helireach_ros.cli.nlp_cache",
)


def build_parser() -> argparse.ArgumentParser:
    """The full argument parser, with every available subcommand."""
    parser = argparse.ArgumentParser(
        prog="helireach",
        description="Helicopter engine-failure reachability: landing plans, H-V envelopes, ROS 2 nodes.",
    )
    parser.add_argument("--version", action="version", version=f"helireach_ros {__version__}")
    subparsers = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for module_name in SUBCOMMAND_MODULES:
        try:
            module = importlib.import_module(module_name)
        except ModuleNotFoundError as error:
            if error.name != module_name:
                raise
            continue
        module.register(subparsers)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Runs ``helireach``; returns the process exit code."""
    arguments = build_parser().parse_args(argv)
    return int(arguments.handler(arguments) or 0)


if __name__ == "__main__":
    sys.exit(main())
