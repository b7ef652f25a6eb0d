"""Status values: one writer and one reader per type, so a flag cannot be written one way and read another."""

from __future__ import annotations

import math

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticStatus

from helireach_ros.core.status_values import format_value, parse_bool
from helireach_ros.display.sections import plan_status_section
from helireach_ros.ros import messages as rm


@pytest.mark.parametrize("flag", [True, False, np.bool_(True), np.bool_(False)])
def test_a_flag_reads_back_as_written(flag) -> None:
    assert parse_bool(format_value(flag)) is bool(flag)


@pytest.mark.parametrize("text", [None, "", "1", "0", "yes", "no", "True", "FALSE", "safe", " true"])
def test_anything_but_true_or_false_is_unknown_never_guessed(text) -> None:
    assert parse_bool(text) is None


def test_floats_keep_round_trip_precision() -> None:
    for number in (0.1, 1 / 3, -2.5e-300, math.inf):
        assert float(format_value(number)) == number
    assert math.isnan(float(format_value(math.nan)))


def test_the_display_reads_the_plan_flags_by_the_same_rule() -> None:
    """A producer that wrote ``1`` or an alias key would be unknown on the cockpit page, not shown as safe."""
    written = rm.diagnostic_status(DiagnosticStatus.OK, "planner", "SAFE", "test", {"safe": True, "verified": True})
    assert plan_status_section(written)["safe"] is True and plan_status_section(written)["verified"] is True
    loose = rm.diagnostic_status(DiagnosticStatus.OK, "planner", "SAFE", "test", {"safe": "1", "status": "safe"})
    assert plan_status_section(loose)["safe"] is None and plan_status_section(loose)["verified"] is None
