"""``helireach display``: serve the cockpit page (H-V diagram, status banner, landing plan) from a ROS 2 node.

The page is at ``http://127.0.0.1:8080/`` by default; only an explicit ``--bind`` makes it listen on anything
but loopback. ``--hold`` keeps the page up after Ctrl-C/SIGTERM stops ROS (last data shown, banner NO DATA,
marked held) until a second Ctrl-C/SIGTERM. Requests whose ``Host`` header is not loopback, the bound address or an
``--allowed-host`` name (with the port) get 421. Options left out keep the node's parameter defaults
(see :class:`helireach_ros.display.node.CockpitDisplay`). Exit codes: 0 after Ctrl-C/SIGTERM, 1 the page
cannot be served (port taken), 2 bad input (``--port`` outside 0-65535, an out-of-range ``--stale-after``).
"""

from __future__ import annotations

import argparse
import sys
from typing import Any

__all__ = ["register", "run"]


def register(subparsers: Any) -> None:
    """Adds ``helireach display`` to the ``helireach`` command's subparsers."""
    parser = subparsers.add_parser(
        "display",
        help="serve the live cockpit page (H-V diagram, safety status, landing plan)",
        description=(
            "Serve a read-only web page that shows the H-V envelope, the aircraft's operating point, "
            "the /helireach/safety_status banner and, after an engine failure, the landing plan."
        ),
    )
    parser.add_argument("--port", type=_port, default=None, help="TCP port 0-65535 (default 8080; 0 = any free port)")
    parser.add_argument(
        "--bind", default=None, help="listen address (default 127.0.0.1; e.g. 0.0.0.0 exposes it to the network)"
    )
    parser.add_argument("--envelope", default=None, metavar="FILE", help="H-V envelope file (default: shipped one)")
    parser.add_argument("--airframe", default=None, help="airframe for rotor limits (default: the envelope's)")
    parser.add_argument("--state-topic", default=None, help="nav_msgs/Odometry state topic (default /helireach/state)")
    parser.add_argument(
        "--stale-after", type=float, default=None, metavar="S", help="STALE after S s of a silent source (default 2)"
    )
    parser.add_argument(
        "--allowed-host",
        action="append",
        default=None,
        metavar="NAME",
        help="also answer this Host header name (repeatable; for a non-loopback --bind, e.g. the machine's name)",
    )
    parser.add_argument(
        "--rotor-caution", type=float, default=None, metavar="PCT", help="amber band inside each rotor limit, %% (3)"
    )
    parser.add_argument("--hold", action="store_true", help="keep serving the last data after ROS stops")
    parser.set_defaults(handler=run)


def _port(text: str) -> int:
    """argparse type of ``--port``: an integer in 0..65535 (the node's ``port`` parameter range)."""
    try:
        port = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not an integer") from None
    if not 0 <= port <= 65535:
        raise argparse.ArgumentTypeError(f"{port} is outside 0-65535")
    return port


def run(arguments: argparse.Namespace) -> int:
    """Handler of ``helireach display``; returns the exit code (1 if the page cannot be served, 2 bad input)."""
    from rclpy.parameter import Parameter

    from helireach_ros.display.node import run_display
    from helireach_ros.ros.parameters import ParameterError

    given = {
        "port": arguments.port,
        "bind": arguments.bind,
        "envelope_file": arguments.envelope,
        "airframe": arguments.airframe,
        "state_topic": arguments.state_topic,
        "stale_after_s": arguments.stale_after,
        "allowed_hosts": ",".join(arguments.allowed_host) if arguments.allowed_host else None,
        "rotor_caution_pct": arguments.rotor_caution,
    }
    overrides = [Parameter(name, value=value) for name, value in given.items() if value is not None]
    try:  # args=[]: the helireach command line is not a ROS command line
        return run_display(args=[], parameter_overrides=overrides, hold=arguments.hold)
    except ParameterError as error:  # e.g. --stale-after -1: the display must not start on a default instead
        print(f"helireach display: error: {error}", file=sys.stderr)
        return 2
