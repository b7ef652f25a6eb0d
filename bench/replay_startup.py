"""Start-up of ``helireach replay``: from launching the command to its first message arriving here.

Run: .venv/bin/python bench/replay_startup.py [--runs 5]

Writes a small log (a status and 50 odometry messages, 20 ms apart), then ``--runs`` times launches
``helireach replay LOG --rate 1`` in a child process (LOCALHOST discovery on a random domain id) while this
process listens on ``/vehicle/odometry``: the time from ``Popen`` to the first odometry message, and to the
child's exit. For the parts, it also times ``python -c 'import helireach_ros.ros.replay'`` and, with nobody
listening, the whole command (which then waits the bounded discovery time, ``DISCOVERY_WAIT_S``). Prints what
it measured, the command and the load average.
"""

from __future__ import annotations

import argparse
import os
import random
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import rclpy
from _common import command_line, loadavg_text, summary
from nav_msgs.msg import Odometry
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.serialization import serialize_message

from helireach_ros.core.mcap_log import McapLogWriter, QosDescription
from helireach_ros.ros import messages as rm
from helireach_ros.ros.nodes.recorder import qos_profile
from helireach_ros.ros.replay import DISCOVERY_WAIT_S

_HELIREACH = str(Path(sys.executable).parent / "helireach")
_STREAM = QosDescription("reliable", "volatile", 10)


def _write_log(path: Path) -> None:
    t0 = time.time_ns()
    with McapLogWriter(path, metadata={"airframe": "uh60a_class"}) as writer:
        writer.add_topic(rm.TOPIC_ODOMETRY, "nav_msgs/msg/Odometry", _STREAM)
        for i in range(50):
            writer.write(rm.TOPIC_ODOMETRY, serialize_message(Odometry()), t0 + i * 20_000_000)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    parser.add_argument("--runs", type=int, default=5)
    arguments = parser.parse_args()
    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    os.environ["ROS_DOMAIN_ID"] = str(random.randint(101, 200))
    log = Path(tempfile.mkdtemp()) / "startup.mcap"
    _write_log(log)

    started = time.monotonic()
    subprocess.run([sys.executable, "-c", "import helireach_ros.ros.replay"], check=True)
    import_s = time.monotonic() - started
    started = time.monotonic()
    subprocess.run([_HELIREACH, "replay", str(log), "--rate", "0"], check=True, capture_output=True)
    alone_s = time.monotonic() - started

    context = Context()
    rclpy.init(context=context)
    node = Node("bench_listener", context=context)
    first = threading.Event()
    node.create_subscription(Odometry, rm.TOPIC_ODOMETRY, lambda _m: first.set(), qos_profile(_STREAM))
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    spinner = threading.Thread(target=executor.spin, daemon=True)
    spinner.start()
    to_first, to_exit = [], []
    try:
        for _ in range(arguments.runs):
            first.clear()
            started = time.monotonic()
            child = subprocess.Popen([_HELIREACH, "replay", str(log), "--rate", "1"], stdout=subprocess.DEVNULL)
            if not first.wait(timeout=30):
                raise SystemExit("no message from the replay within 30 s")
            to_first.append(time.monotonic() - started)
            child.wait(timeout=30)
            to_exit.append(time.monotonic() - started)
    finally:
        executor.shutdown()
        spinner.join(timeout=5)
        node.destroy_node()
        rclpy.try_shutdown(context=context)

    print(f"command: {command_line()}")
    print(f"load average (1/5/15 min): {loadavg_text()}")
    print(f"python -c 'import helireach_ros.ros.replay': {import_s:.3f} s (interpreter start + imports)")
    print(f"replay with nobody listening (waits at most DISCOVERY_WAIT_S = {DISCOVERY_WAIT_S} s): {alone_s:.3f} s")
    print(
        f"launch -> first message here, {arguments.runs} runs: median {summary(to_first)['median']:.3f} s, "
        f"min {min(to_first):.3f} s, max {max(to_first):.3f} s"
    )
    print(f"launch -> exit (1 s of log at rate 1): median {summary(to_exit)['median']:.3f} s")


if __name__ == "__main__":
    main()
