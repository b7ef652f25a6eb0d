"""Exit codes and command lines of the real console scripts (subprocesses), as docs/guides/using.md's table lists them.

0 = success / safe / stopped by Ctrl-C or SIGTERM, 1 = not safe (plan, envelope query), 2 = bad input, with
one line on stderr and no traceback.
"""

from __future__ import annotations

import math
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from helireach_ros.core.envelope.data import default_envelope_path

pytestmark = [pytest.mark.system]

BIN = Path(sys.executable).parent
NODE_SCRIPTS = ("helireach_monitor", "helireach_envelope_status", "helireach_planner", "helireach_sim_vehicle",
                "helireach_recorder")  # fmt: skip
TIMEOUT_S = 60.0


def run(*command: str, timeout: float = TIMEOUT_S) -> subprocess.CompletedProcess:
    return subprocess.run([str(BIN / command[0]), *command[1:]], capture_output=True, text=True, timeout=timeout)


def assert_one_line_error(result: subprocess.CompletedProcess, *fragments: str) -> None:
    assert result.returncode == 2, (result.returncode, result.stderr)
    assert "Traceback" not in result.stderr
    ours = [line for line in result.stderr.splitlines() if "error:" in line]
    assert len(ours) == 1, result.stderr
    for fragment in fragments:
        assert fragment in ours[0], result.stderr


@pytest.fixture
def isolated_ros(localhost_ros_domain, tmp_path, monkeypatch):
    monkeypatch.setenv("ROS_LOG_DIR", str(tmp_path / "ros_log"))
    return tmp_path


@pytest.mark.parametrize("script", NODE_SCRIPTS)
def test_node_help_prints_usage_with_parameters_and_exits_0(script, isolated_ros):
    result = run(script, "--help")
    assert result.returncode == 0, result.stderr
    assert result.stdout.startswith(f"usage: {script}") and f"ROS 2 node '{script}'" in result.stdout
    assert "--ros-args -p" in result.stdout and "exit codes:" in result.stdout
    assert "diagnostics_period (float in [0.05, 60], default 1.0)" in result.stdout or script == "helireach_recorder"
    assert not (isolated_ros / "ros_log").exists()  # rclpy was never initialised (it would create its log folder)


def test_monitor_help_lists_each_parameter_with_range_default_and_description(isolated_ros):
    text = run("helireach_monitor", "-h").stdout
    assert "  stale_timeout (float in [0.01, 60], default 0.5)\n      no valid state for this long = STALE, s" in text
    assert "  min_height (float in [-100, 0], default -1.0)" in text  # a default taken from StateLimits()


@pytest.mark.parametrize(
    ("arguments", "fragments"),
    [
        (["--ros-args", "-p"], ["-p needs a value"]),
        (["--ros-args", "--params-file", "/nonexistent/params.yaml"], ["/nonexistent/params.yaml", "No such file"]),
        (["--ros-args", "-p", "stale_timeout:=-5.0"], ["'stale_timeout'", "-5.0", "out of range", "[0.01, 60]"]),
        (["--ros-args", "-p", "stale_timeout:=abc"], ["'stale_timeout'", "'abc' (a string)", "expected a float"]),
        (["--ros-args", "--no-such-ros-flag"], ["--no-such-ros-flag"]),
        (["-p", "stale_timeout:=0.2"], ["unexpected argument '-p'", "after --ros-args"]),
    ],
)
def test_monitor_bad_command_line_or_parameter_exits_2_with_one_line(arguments, fragments, isolated_ros):
    assert_one_line_error(run("helireach_monitor", *arguments), *fragments)


@pytest.mark.parametrize("script", NODE_SCRIPTS)
def test_every_node_script_exits_2_on_an_out_of_range_parameter(script, isolated_ros):
    name = "flush_period" if script == "helireach_recorder" else "diagnostics_period"
    assert_one_line_error(run(script, "--ros-args", "-p", f"{name}:=-1.0"), f"'{name}' of {script} = -1.0")


def test_a_broken_params_file_exits_2_naming_it(isolated_ros):
    broken = isolated_ros / "broken.yaml"
    broken.write_text("helireach_monitor:\n  ros__parameters: {stale_timeout: [1,\n")
    assert_one_line_error(run("helireach_monitor", "--ros-args", "--params-file", str(broken)), "not valid YAML")
    not_nodes = isolated_ros / "list.yaml"
    not_nodes.write_text("- 1\n- 2\n")
    assert_one_line_error(run("helireach_monitor", "--ros-args", "--params-file", str(not_nodes)), "ros__parameters")


def warning_then_sigint(command: list[str], misspelt: str) -> tuple[list[str], int]:
    """Runs ``command`` until a stderr line names ``misspelt``, then SIGINT; returns (stderr lines, exit code)."""
    process = subprocess.Popen(command, stderr=subprocess.PIPE, text=True)
    lines: list[str] = []
    try:
        deadline = time.monotonic() + TIMEOUT_S
        while not any(misspelt in line for line in lines) and time.monotonic() < deadline:
            line = process.stderr.readline()
            assert line or process.poll() is None, f"ended before warning: {''.join(lines)}"
            lines.append(line)
        process.send_signal(signal.SIGINT)
        return lines, process.wait(timeout=TIMEOUT_S)
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()
        process.stderr.close()


def test_monitor_runs_with_an_int_for_a_float_warns_about_a_misspelt_name_and_exits_0_on_sigint(isolated_ros):
    command = [str(BIN / "helireach_monitor"), "--ros-args", "-p", "stale_timeout:=1", "-p", "stale_timout:=0.2"]
    lines, code = warning_then_sigint(command, "stale_timout")
    assert "[WARN]" in lines[-1] and "did you mean 'stale_timeout'?" in lines[-1], lines
    assert code == 0


def test_bringup_warns_once_about_a_name_no_node_declares(isolated_ros):
    command = [str(BIN / "helireach"), "bringup", "--no-record", "--ros-args", "-p", "stale_timout:=0.2",
               "-p", "deadline:=0.2"]  # fmt: skip
    lines, _ = warning_then_sigint(command, "stale_timout")  # (a SIGINT during start-up ends it at once)
    assert "did you mean 'stale_timeout'?" in lines[-1], lines
    assert not any("'deadline'" in line for line in lines)  # the planner's: a bare -p reaches every node


@pytest.mark.parametrize(
    ("arguments", "fragments"),
    [
        (["--ros-args", "-p"], ["-p needs a value"]),
        (["--params-file", "/nonexistent/params.yaml"], ["/nonexistent/params.yaml"]),
        (["--ros-args", "-p", "helireach_monitor:stale_timeout:=-5.0"], ["'stale_timeout' of helireach_monitor"]),
    ],
)
def test_bringup_bad_command_line_or_parameter_exits_2(arguments, fragments, isolated_ros):
    assert_one_line_error(run("helireach", "bringup", "--no-record", *arguments), *fragments)


def test_display_port_out_of_range_exits_2(isolated_ros):
    result = run("helireach", "display", "--port", "99999")
    assert result.returncode == 2 and "99999 is outside 0-65535" in result.stderr


@pytest.mark.parametrize(
    ("height_ft", "speed_kt", "code", "status"),
    [(500, 75, 0, "safe"), (150, 0, 1, "unsafe"), (5000, 75, 1, "outside"), (math.nan, 10, 2, None)],
)
def test_envelope_query_exit_code_says_whether_the_point_is_safe(height_ft, speed_kt, code, status, isolated_ros):
    result = run("helireach", "envelope", "query", str(default_envelope_path()), "--height-ft", str(height_ft),
                 "--speed-kt", str(speed_kt))  # fmt: skip
    assert result.returncode == code, result.stderr
    if status is not None:
        assert f": {status} (" in result.stdout
    else:
        assert "must be finite" in result.stderr


def test_envelope_query_of_a_missing_file_exits_2(isolated_ros):
    result = run("helireach", "envelope", "query", os.fspath(isolated_ros / "none.npz"), "--height-ft", "1",
                 "--speed-kt", "1")  # fmt: skip
    assert result.returncode == 2 and "none.npz" in result.stderr


def test_params_files_in_every_rcl_layout_pass_the_check(tmp_path):
    from helireach_ros.core.resources import config_path
    from helireach_ros.ros.node_command_line import check_ros_arguments

    nested = tmp_path / "nested.yaml"
    nested.write_text("/aircraft1:\n  helireach_monitor:\n    ros__parameters: {stale_timeout: 0.4}\n")
    check_ros_arguments(["--params-file", str(config_path("nodes.yaml")), "--params-file", str(nested), "-p", "a:=1"])


def test_the_display_script_has_help_and_refuses_a_bad_parameter(isolated_ros):
    usage = run("helireach_display", "--help")
    assert usage.returncode == 0 and usage.stdout.startswith("usage: helireach_display") and "port" in usage.stdout
    assert not (isolated_ros / "ros_log").exists()
    assert_one_line_error(run("helireach_display", "--ros-args", "-p", "port:=99999"), "'port' of helireach_display")


def test_the_demo_refuses_a_missing_parameter_file(isolated_ros):
    result = subprocess.run(
        [sys.executable, "-m", "helireach_ros.cli.demo", "--no-display", "--params-file", str(isolated_ros / "nope")],
        capture_output=True,
        text=True,
        timeout=TIMEOUT_S,
    )
    assert result.returncode == 2 and "nope" in result.stderr and "Traceback" not in result.stderr


# A node that keeps its executor rebuilding wait sets (a 0.2 ms timer), stopped by a real SIGTERM after 20-40 ms,
# 150 times in one process: with a bare executor.spin() about one stop in five raised RCLError ("failed to initialize
# wait set") because rclpy's signal handler shuts the context down from another thread (ros2/rclpy#1166).
_SIGTERM_LOOP = """
import os, random, signal, sys, threading
from rclpy.node import Node
from helireach_ros.ros import added_order_executor, parameters, qos  # imported now: the first stop is timed too
from helireach_ros.ros.executors import run_node

class BusyNode(Node):
    def __init__(self):
        super().__init__("busy_node")
        self.create_timer(0.0002, lambda: None)

for _ in range(int(sys.argv[1])):
    threading.Timer(random.uniform(0.02, 0.04), os.kill, (os.getpid(), signal.SIGTERM)).start()
    assert run_node(BusyNode, ["busy_node"]) == 0
print("all stopped cleanly")
"""


def test_run_node_treats_a_sigterm_that_races_the_wait_set_as_a_normal_stop(isolated_ros):
    script = isolated_ros / "sigterm_loop.py"  # a file: run_node reads the node's source for its name
    script.write_text(_SIGTERM_LOOP)
    result = subprocess.run([sys.executable, str(script), "150"], capture_output=True, text=True, timeout=TIMEOUT_S)
    assert result.returncode == 0 and "all stopped cleanly" in result.stdout, result.stderr[-2000:]
    assert "Traceback" not in result.stderr
