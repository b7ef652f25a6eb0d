"""The ``helireach plan`` command, run as users run it."""

import json
import subprocess
import sys

import pytest

from helireach_ros.core.aircraft.airframe import load_airframe
from helireach_ros.core.aircraft.model import steady_autorotation
from helireach_ros.core.units import FT, KT


def _helireach(*arguments: str, timeout_s: float = 120.0) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "helireach_ros.cli.main", *arguments], capture_output=True, text=True, timeout=timeout_s
    )


def test_plan_json_and_figure(tmp_path):
    figure = tmp_path / "plan.png"
    result = _helireach("plan", "--height-ft", "500", "--speed-kt", "75", "--json", "--plot", str(figure))
    assert result.returncode == 0, result.stderr
    summary = json.loads(result.stdout)
    assert summary["safe"] is True and summary["verified"] is True
    assert summary["value"] <= 0.0
    # no faster than the steady autorotation's descent at 75 kt, and no more than twice as slow (the flare)
    steady_descent_time = 500 * FT / steady_autorotation(load_airframe("uh60a_class"), 75 * KT)[0]
    assert steady_descent_time <= summary["time_to_land_s"] <= 2.0 * steady_descent_time
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


def test_any_state_in_a_descent_with_a_slow_rotor_and_the_state_json_round_trip(tmp_path):
    # 20 ft, 90 kt is safe from level trim; in a 2,000 ft/min descent it is not (exit 1).
    descent = _helireach("plan", "--height-ft", "20", "--speed-kt", "90", "--climb-rate-fpm", "-2000", "--json")
    assert descent.returncode == 1, descent.stderr
    state = json.loads(descent.stdout)["initial_state"]
    assert state["descent_rate"] == pytest.approx(2000 * 0.3048 / 60)
    slow = _helireach("plan", "--height-ft", "500", "--speed-kt", "75", "--rotor-speed-pct", "95", "--json")
    assert slow.returncode == 0, slow.stderr
    assert json.loads(slow.stdout)["initial_state"]["rotor_speed"] == pytest.approx(0.95 * 27.0)
    # The initial state (or a whole --json output) fed back gives the same answer.
    path = tmp_path / "state.json"
    path.write_text(descent.stdout)
    again = _helireach("plan", "--state-json", str(path), "--json")
    assert again.returncode == 1 and json.loads(again.stdout)["value"] == pytest.approx(
        json.loads(descent.stdout)["value"], abs=1e-9
    )


@pytest.mark.parametrize(
    ("document", "message"),
    [
        ('{"height": 10, "forward_speed": 5, "descent_rate": 1}', "rotor_speed"),
        ('{"height": 10, "forward_speed": 5, "descent_rate": 1, "rotor_speed": 27, "speed": 3}', "unknown"),
        ('{"height": "high", "forward_speed": 5, "descent_rate": 1, "rotor_speed": 27}', "finite number"),
        ("[1, 2]", "JSON object"),
        ("{not json", "not JSON"),
    ],
)
def test_a_bad_state_file_is_a_clear_error(tmp_path, document, message):
    path = tmp_path / "state.json"
    path.write_text(document)
    result = _helireach("plan", "--state-json", str(path))
    assert result.returncode == 2 and message in result.stderr and "Traceback" not in result.stderr


def test_the_default_plan_is_flyable_and_the_delay_and_limits_are_reported():
    result = _helireach("plan", "--height-ft", "500", "--speed-kt", "75", "--reaction-delay-s", "0.3", "--json")
    assert result.returncode == 0, result.stderr
    summary = json.loads(result.stdout)
    assert summary["method"] == "flyable" and summary["reaction_delay_s"] == 0.3
    flyability = summary["flyability"]
    assert flyability["within_limits"] and flyability["violations"] == []
    assert -12.0 <= flyability["touchdown_pitch_deg"] <= 5.0  # theta, positive nose down: the touchdown window
    assert (
        flyability["max_pitch_rate_deg_s"] <= 20.0 * (1 + 1e-6) and flyability["max_nose_up_pitch_deg"] <= 25.0 + 1e-6
    )
    verified = json.loads(
        _helireach("plan", "--height-ft", "500", "--speed-kt", "75", "--method", "verified", "--json").stdout
    )
    assert not verified["flyability"]["within_limits"]  # the paper-limit plan: steps and 40-degree attitudes
    violations = verified["flyability"]["violations"]
    assert any(violation.startswith("collective rate inf/s") for violation in violations), violations
    assert any(violation.startswith("nose-up attitude 40.0 deg") for violation in violations), violations


def test_the_rotor_model_is_selectable_and_the_paper_method_keeps_the_papers():
    state = ("--airframe", "s300c_class", "--height-ft", "300", "--speed-kt", "40", "--json")
    momentum = json.loads(_helireach("plan", *state, "--rotor-model", "momentum").stdout)
    shipped = json.loads(_helireach("plan", *state).stdout)
    assert momentum["airframe_digest"] != shipped["airframe_digest"]  # a different model, said so in the output
    assert momentum["time_to_land_s"] != pytest.approx(shipped["time_to_land_s"], abs=1e-3)
    paper = json.loads(_helireach("plan", *state, "--method", "paper", "--rotor-model", "momentum").stdout)
    reference = json.loads(_helireach("plan", *state, "--method", "paper").stdout)
    assert paper["value"] == pytest.approx(reference["value"], abs=1e-9)
    assert paper["time_to_land_s"] == pytest.approx(reference["time_to_land_s"], abs=1e-9)
    bad = _helireach("plan", "--height-ft", "300", "--speed-kt", "40", "--rotor-model", "uniform")
    assert bad.returncode == 2 and "--rotor-model" in bad.stderr


@pytest.mark.build  # compiles the NLP's C code on a machine whose cache does not have it yet
def test_nlp_cache_builds_the_default_and_refuses_an_unknown_airframe_with_one_line():
    # a hang guard, not a timing: compiling the momentum rotor's NLP takes minutes on 2 cores (bench/ measures it)
    built = _helireach("nlp-cache", timeout_s=900.0)
    assert built.returncode == 0, built.stderr
    assert built.stdout.startswith("uh60a_class (terminal): ") and "linear solver" in built.stdout
    refused = _helireach("nlp-cache", "--airframe", "no_such_airframe")
    assert refused.returncode == 2 and refused.stdout == ""
    assert len(refused.stderr.strip().splitlines()) == 1 and "no_such_airframe" in refused.stderr
    unknown = _helireach("nlp-cache", "--objective", "nowhere")  # refused before anything is built
    assert unknown.returncode == 2 and unknown.stdout == "" and "objective" in unknown.stderr
