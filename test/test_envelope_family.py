"""Envelope families: a sweep over weight and density altitude written, resumed and answered as one product (real
IPOPT solves through the CLI, real files), and the status node answering from the members of today's weight."""

from __future__ import annotations

import json
import math
import signal
import subprocess
import sys
from functools import partial
from pathlib import Path

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticStatus
from rclpy.parameter import Parameter
from test_envelope import interrupt_cli, run_cli
from test_ros_nodes import Harness

from helireach_ros.core.envelope.data import EnvelopeError, EnvelopeQuery, read_envelope_file
from helireach_ros.core.envelope.family import FAMILY_INDEX, EnvelopeFamily, read_family_index
from helireach_ros.core.units import FT, KT, LBF
from helireach_ros.ros import messages as rm
from helireach_ros.ros.nodes.envelope_status import EnvelopeStatusNode
from helireach_ros.ros.nodes.monitor import VehicleMonitor

GRID = ("--heights-ft", "200:600:3", "--speeds-kt", "20:60:3")
CONDITIONS = ("--weights-lb", "15000,16000", "--density-altitude-ft", "0,3000")
# grid nodes and the points between them
POINTS = [(height, speed) for height in np.linspace(200, 600, 5) for speed in np.linspace(20, 60, 5)]


@pytest.fixture(scope="module")
def family_folder(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("family") / "uh60a"
    result = run_cli("envelope", "compute", *GRID, *CONDITIONS, "--workers", "2", "--out", str(folder), "--quiet")
    assert result.returncode == 0, result.stderr
    return folder


def _same(first: EnvelopeQuery, second: EnvelopeQuery) -> bool:
    numbers = [(first.value, second.value), (first.margin, second.margin)]
    return (first.status, first.by_interpolation, first.verdict) == (
        second.status,
        second.by_interpolation,
        second.verdict,
    ) and all(a == b or (math.isnan(a) and math.isnan(b)) for a, b in numbers)


def test_a_family_answers_as_its_member_there_and_between_members_never_safer_than_the_worst(
    family_folder: Path, airframe
) -> None:
    family = EnvelopeFamily.load(family_folder, airframe)
    _, members, command = read_family_index(family_folder)
    assert len(members) == 4 and all(member.complete and len(member.sha256) == 64 for member in members)
    assert command is not None and "--weights-lb" in command
    assert family.weights == (15000 * LBF, 16000 * LBF) and family.density_altitudes == (0.0, 3000 * FT)
    # the conditions matter here (else "never safer" proves nothing): the heavier member is safe at fewer nodes
    light = family.at(15000 * LBF, 0.0).members[0][1]
    heavy = family.at(16000 * LBF, 0.0).members[0][1]
    assert np.sum(heavy.status == "safe") < np.sum(light.status == "safe")

    for member, envelope in family.members:
        at_member = family.at(member.gross_weight, member.density_altitude)
        assert [m for m, _ in at_member.members] == [member]
        for height, speed in POINTS:
            assert _same(at_member.query(height * FT, speed * KT), envelope.query(height * FT, speed * KT))

    for weight_lb, altitude_ft, neighbours in ((15500, 1500, 4), (15000, 1500, 2), (15500, 3000, 2)):
        between = family.at(weight_lb * LBF, altitude_ft * FT)
        assert len(between.members) == neighbours and "worst of the members" in between.conditions
        for height, speed in POINTS:
            answers = [envelope.query(height * FT, speed * KT) for _, envelope in between.members]
            answer = between.query(height * FT, speed * KT)
            assert (answer.status == "safe") == all(other.status == "safe" for other in answers)
            assert not answer.margin > min(other.margin for other in answers)  # NaN (outside the grid) passes
            assert not answer.value < max(other.value for other in answers)

    for weight_lb, altitude_ft in ((16500, 0), (14000, 0), (15500, -100), (15500, 3500)):
        with pytest.raises(EnvelopeError, match="outside the family's range"):
            family.at(weight_lb * LBF, altitude_ft * FT)


def test_the_cli_queries_a_family_at_its_conditions_and_refuses_conditions_outside_it(family_folder: Path) -> None:
    def query(*arguments: str) -> subprocess.CompletedProcess:
        return run_cli("envelope", "query", *arguments, "--height-ft", "400", "--speed-kt", "40", "--json")

    member_file = family_folder / "uh60a_class_16000lb_da3000ft_pf0.npz"
    from_file = json.loads(query(str(member_file)).stdout)
    from_family = json.loads(query(str(family_folder), "--weight-lb", "16000", "--density-altitude-ft", "3000").stdout)
    assert {key: from_family[key] for key in ("status", "value", "margin")} == {
        key: from_file[key] for key in ("status", "value", "margin")
    }
    between = query(str(family_folder / FAMILY_INDEX), "--weight-lb", "15500", "--density-altitude-ft", "1500")
    assert "worst of the members" in json.loads(between.stdout)["conditions"]
    outside = query(str(family_folder), "--weight-lb", "17000", "--density-altitude-ft", "0")
    assert outside.returncode == 2 and "outside the family's range (15000-16000 lbf, DA 0-3000 ft)" in outside.stderr
    missing = query(str(family_folder))
    assert missing.returncode == 2 and "--weight-lb" in missing.stderr
    assert query(str(member_file), "--weight-lb", "16000", "--density-altitude-ft", "0").returncode == 2
    summary = run_cli("envelope", "family", str(family_folder), "--json")
    assert summary.returncode == 0, summary.stderr
    document = json.loads(summary.stdout)
    assert document["range"] == "15000-16000 lbf, DA 0-3000 ft" and len(document["members"]) == 4
    assert isinstance(document["monotonicity_exceptions"], list)
    # the lightest, lowest member always bounds itself; a line claims a member bounds every member below it
    family = EnvelopeFamily.load(family_folder)
    assert document["valid_up_to"] == family.valid_up_to() and document["valid_up_to"]
    for line in document["valid_up_to"]:
        weight, altitude = (float(word) for word in line.split() if word.replace(".", "").isdigit())
        top = family.at(weight * LBF, altitude * FT).members[0][1]
        for member, envelope in family.members:
            if member.gross_weight <= weight * LBF and member.density_altitude <= altitude * FT:
                assert not np.any((top.status == "safe") & (envelope.status != "safe")), (line, member.conditions)
    figure = family_folder.parent / "family.png"
    assert run_cli("envelope", "plot", str(family_folder), "--out", str(figure)).returncode == 0
    assert figure.stat().st_size > 10_000


def _same_arrays(first: Path, second: Path) -> bool:
    """The two envelope files hold the same statuses, values and boundary (NaN where the other has NaN)."""
    a, b = read_envelope_file(first), read_envelope_file(second)
    return (
        np.array_equal(a.status, b.status)
        and np.array_equal(a.value, b.value, equal_nan=True)
        and np.array_equal(np.asarray(a.boundary), np.asarray(b.boundary), equal_nan=True)
    )


def test_a_family_is_computed_together_and_each_member_equals_its_envelope_alone(
    family_folder: Path, tmp_path: Path
) -> None:
    """The members' tasks run together in every phase (one progress display), and what a member gets is what its
    conditions give when computed alone."""
    _, members, _ = read_family_index(family_folder)
    compute = read_envelope_file(family_folder / members[0].file).metadata["compute"]
    assert compute["members_computed_together"] == 4
    assert compute["tasks"]["sweep"] == 4 * 3  # every member's 3 speed columns in one phase
    alone = tmp_path / "alone.npz"
    result = run_cli("envelope", "compute", *GRID, "--weights-lb", "16000", "--density-altitude-ft", "3000",
                     "--workers", "2", "--out", str(alone), "--quiet")  # fmt: skip
    assert result.returncode == 0, result.stderr
    assert _same_arrays(alone, family_folder / "uh60a_class_16000lb_da3000ft_pf0.npz")


def test_a_family_sweep_stopped_midway_saves_every_member_and_resumes_to_the_same_family(
    family_folder: Path, tmp_path: Path, airframe
) -> None:
    """SIGTERM (a cluster job pre-empted, or Ctrl-C) in the middle of the sweep: every member's partial file is
    saved, the family does not load, and ``--resume`` completes it to exactly the uninterrupted family."""
    folder = tmp_path / "stopped"
    command = [sys.executable, "-m", "helireach_ros.cli.main", "envelope", "compute", *GRID, *CONDITIONS,
               "--workers", "1", "--out", str(folder)]  # fmt: skip
    # stop once the sweep has solved a node (its progress line past 0)
    rest = interrupt_cli(command, lambda line: line.startswith("sweep: ") and not line.startswith("sweep: 0/"),
                         signal.SIGTERM)  # fmt: skip
    assert "continue with --resume" in rest
    files = [folder / member.file for member in read_family_index(folder)[1]]
    assert len(files) == 4 and all(read_envelope_file(f, allow_partial=True).complete is False for f in files)
    with pytest.raises(EnvelopeError, match="not complete"):
        EnvelopeFamily.load(folder, airframe)

    resumed = subprocess.run([*command, "--resume"], capture_output=True, text=True, timeout=300)
    assert resumed.returncode == 0, resumed.stderr
    assert resumed.stderr.count("resuming (") == 4
    done = [int(line.split("resuming (")[1].split()[0]) for line in resumed.stderr.splitlines() if "resuming (" in line]
    assert sum(done) > 0
    family = EnvelopeFamily.load(folder, airframe)
    assert len(family.members) == 4
    for member, _ in family.members:
        assert _same_arrays(folder / member.file, family_folder / member.file), member.conditions


def _judged_a_state(statuses: list) -> bool:
    return bool(statuses) and "height_m" in rm.status_values(statuses[-1])


def test_the_status_node_answers_from_the_member_of_todays_weight(family_folder: Path, context, airframe) -> None:
    """A heavier aircraft gets the heavier member's answer: at a state the 15,000 lbf member calls safe and the
    16,000 lbf one does not, the status is SAFE or CAUTION at 15,000 lbf and AVOID at 16,000 lbf; outside the family's
    weights there is no envelope (STALE, saying the range)."""
    family = EnvelopeFamily.load(family_folder, airframe)
    light, heavy = family.at(15000 * LBF, 0.0), family.at(16000 * LBF, 0.0)
    state = next(
        (height, speed)
        for height, speed in POINTS
        if light.query(height * FT, speed * KT).status == "safe"
        and heavy.query(height * FT, speed * KT).status != "safe"
    )
    for weight_lb, safe in ((15000, True), (16000, False), (17000, None)):
        overrides = [
            Parameter("envelope_file", value=str(family_folder)),
            Parameter("gross_weight", value=weight_lb * LBF),
            Parameter("density_altitude", value=0.0),
        ]
        status_node = EnvelopeStatusNode(context=context, parameter_overrides=overrides)
        harness = Harness(context, VehicleMonitor(context=context), status_node)
        statuses = harness.listen(DiagnosticStatus, rm.TOPIC_SAFETY_STATUS)
        try:
            assert harness.keep_publishing(state[0] * FT, state[1] * KT, until=partial(_judged_a_state, statuses))
            values = rm.status_values(statuses[-1])
            if safe is None:
                assert status_node.envelope is None and statuses[-1].level == DiagnosticStatus.STALE
                assert "outside the family's range (15000-16000 lbf" in statuses[-1].message
                continue
            assert f"{weight_lb} lbf" in values["envelope_conditions"], values["envelope_conditions"]
            assert (values["envelope_status"] == "safe") == safe
            expected = (DiagnosticStatus.OK, DiagnosticStatus.WARN) if safe else (DiagnosticStatus.ERROR,)
            assert statuses[-1].level in expected, statuses[-1].message
        finally:
            harness.close()


@pytest.mark.system
def test_the_cockpit_draws_the_family_member_the_status_answers_from(family_folder: Path, no_ros_discovery) -> None:
    """A display given the family draws its heaviest, highest member until a safety status names the members it
    answers from; then that member (labelled with its conditions), pushed to the open page."""
    import asyncio

    import aiohttp
    from test_display import RosHarness, frame_until, read_frame, status_message, websocket_url

    family = EnvelopeFamily.load(family_folder)
    light = family.at(15000 * LBF, 0.0)
    between = family.at(15500 * LBF, 1500 * FT)
    harness = RosHarness(envelope_file=str(family_folder))
    try:

        async def scenario() -> tuple[dict, dict, dict]:
            async with aiohttp.ClientSession() as http, http.ws_connect(websocket_url(harness.display)) as socket:
                first = (await read_frame(socket))["envelope"]
                frames = []
                for view in (light, between):
                    status = status_message(DiagnosticStatus.OK, "SAFE", 120.0, 20.0, 30.0, view.envelope_id)
                    harness.vehicle.status_publisher.publish(status)
                    frame = await frame_until(
                        socket,
                        lambda frame, view=view: frame.get("envelope", {}).get("envelope_id") == view.envelope_id,
                        f"the diagram of {view.conditions}",
                    )
                    frames.append(frame["envelope"])
                return first, frames[0], frames[1]

        first, drawn_light, drawn_between = asyncio.run(scenario())
        assert first["available"] and first["conditions"] == "16000 lbf, DA 3000 ft"
        assert drawn_light["conditions"] == "15000 lbf, DA 0 ft"
        light_member = light.members[0][1]
        assert np.array_equal(np.asarray(drawn_light["status"]) == 0, light_member.status == "safe")
        assert not np.array_equal(np.asarray(first["status"]) == 0, light_member.status == "safe")
        assert drawn_between["conditions"] == "16000 lbf, DA 3000 ft (worst of 4)"
    finally:
        harness.close()
