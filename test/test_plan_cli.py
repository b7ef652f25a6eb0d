"""The ``helireach plan`` command, run as users run it."""

import json
import subprocess
import sys

import pytest


def _helireach(*arguments: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "helireach_ros.cli.main", *arguments], capture_output=True, text=True, timeout=120
    )


def test_plan_json_and_figure(tmp_path):
    figure = tmp_path / "plan.png"
    result = _helireach("plan", "--height-ft", "500", "--speed-kt", "75", "--json", "--plot", str(figure))
    assert result.returncode == 0, result.stderr
    summary = json.loads(result.stdout)
    assert summary["safe"] is True and summary["verified"] is True
    assert summary["value"] <= 0.0
    assert 8.0 <= summary["time_to_land_s"] <= 16.0
    assert set(summary["touchdown"]) >= {"descent_rate_ft_s", "forward_speed_kt", "rotor_speed_pct"}
    assert summary["touchdown"]["descent_rate_ft_s"] <= 8.0
    assert summary["replay"]["value"] <= 0.0
    assert summary["solver"]["status"] == "Solve_Succeeded"
    assert summary["solver"]["iterations"] > 0 and summary["solver"]["solve_time_ms"] > 0
    trajectory = summary["trajectory"]
    assert len(trajectory["states"]) == 6 and len(trajectory["controls"]) == 2
    assert all(len(row) == len(trajectory["t_s"]) for row in trajectory["states"] + trajectory["controls"])
    assert figure.stat().st_size > 10_000


def test_unsafe_state_exits_1_and_paper_method_is_selectable():
    result = _helireach("plan", "--height-ft", "150", "--speed-kt", "0", "--json", "--method", "paper")
    assert result.returncode == 1
    summary = json.loads(result.stdout)
    assert summary["method"] == "paper" and summary["safe"] is False


@pytest.mark.parametrize(
    ("arguments", "message"),
    [
        (("--airframe", "no_such_airframe"), "no_such_airframe"),
        (("--power-fraction", "2"), "power fraction"),
        (("--height-ft", "nan"), "finite"),
    ],
)
def test_bad_input_is_a_clear_error(arguments, message):
    base = {"--height-ft": "500", "--speed-kt": "75"}
    base.update(dict(zip(arguments[::2], arguments[1::2], strict=True)))
    result = _helireach("plan", *[item for pair in base.items() for item in pair])
    assert result.returncode == 2
    assert "error" in result.stderr and message in result.stderr
    assert "Traceback" not in result.stderr
