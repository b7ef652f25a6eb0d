"""``helireach log recover IN.mcap [OUT.mcap]``: make a killed recorder's log a finished, indexed file.

The output (default ``IN.recovered.mcap``) opens in mcap's indexed reader, ``rosbags``, ``ros2 bag`` and
``helireach replay``; the command prints how many messages and what time span were recovered and what was
lost (:func:`helireach_ros.core.mcap_log.recover_log`). Exit codes: 0 recovered (or the file was already
finished: nothing is written), 2 bad input (missing or not MCAP, nothing recoverable, the output exists
without ``--force`` or is the input).
"""

from __future__ import annotations

import argparse
import sys

__all__ = ["register"]


def _recover(arguments: argparse.Namespace) -> int:
    from helireach_ros.core.mcap_log import McapLogError, is_finished_log, log_damage, recover_log

    try:
        if is_finished_log(arguments.log) and not log_damage(arguments.log):
            print(f"{arguments.log}: already finished (it has a footer and index) and intact; nothing to recover")
            return 0
        report = recover_log(arguments.log, arguments.out, overwrite=arguments.force)
    except McapLogError as error:
        print(f"helireach log recover: {error}", file=sys.stderr)
        return 2
    print(report.describe())
    return 0


def register(subparsers: argparse._SubParsersAction) -> None:
    """Adds ``log`` with its ``recover`` subcommand."""
    parser = subparsers.add_parser("log", help="MCAP run logs: recover a killed recording")
    commands = parser.add_subparsers(dest="log_command", required=True, metavar="SUBCOMMAND")
    recover = commands.add_parser(
        "recover",
        help="rewrite a log the recorder never closed (kill -9, power cut) into a finished, indexed file",
        description="Keeps every complete chunk's messages, the channels, schemas and helireach metadata, and "
        "writes summary, index and the rosbag2 metadata record; prints what was recovered and lost.",
    )
    recover.add_argument("log", help="the unfinished .mcap file")
    recover.add_argument("out", nargs="?", default=None, help="the finished file (default: LOG.recovered.mcap)")
    recover.add_argument("--force", action="store_true", help="replace OUT if it exists")
    recover.set_defaults(handler=_recover)
