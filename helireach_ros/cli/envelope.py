"""``helireach envelope compute | query | plot``: H-V envelopes from the command line.

Examples::

    helireach envelope compute --airframe uh60a_class --speeds-kt 0:120:25 --heights-ft 0:800:41 --out hv.npz
    helireach envelope compute --weights-lb 14000,16000 --density-altitude-ft 0,4000 --scheduler tcp://host:8786 \\
        --out sweep/            # one file per combination in the folder
    helireach envelope compute --climb-rates-fpm=-2000,-1000,0,1500 --dask-local 2 --out hv3d.npz   # 3-D
    helireach envelope compute --method paper --reaction-delay-s 0 --out paper.npz
    helireach envelope compute --heights-ft 100:800:8 --speeds-kt 0:120:7 --robust --dask-local 2 --out robust.npz
    helireach envelope robust hv.npz --out hv_robust.npz --workers 2   # robust verdicts for an existing file
    helireach envelope query hv.npz --height-ft 200 --speed-kt 20 --json
    helireach envelope query hv_robust.npz --height-ft 500 --speed-kt 75 --verdict robust
    helireach envelope plot hv.npz --out hv.png
    helireach envelope plot hv3d.npz --climb-rate-fpm -1000 --out slice.png    # or --all-slices
    helireach envelope plot paper.npz hv.npz --out overlay.png                # boundaries of several files

Heavy imports (CasADi, Dask, matplotlib) stay inside the handlers so ``helireach --help`` is fast.
"""

from __future__ import annotations

import argparse
import json
import math
import shlex
import sys
from pathlib import Path
from typing import Any

from helireach_ros.cli.options import add_rotor_model_option
from helireach_ros.core.ocp.settings import METHODS

__all__ = ["register"]


def _add_executor_arguments(parser: argparse.ArgumentParser) -> None:
    where = parser.add_mutually_exclusive_group()
    where.add_argument("--workers", type=int, default=None, help="local worker processes (default: every core)")
    where.add_argument("--scheduler", default=None, help="Dask scheduler address, e.g. tcp://10.0.0.5:8786")
    where.add_argument(
        "--dask-local", type=int, default=None, metavar="N", help="run on a Dask LocalCluster of N worker processes"
    )


def _add_robust_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--uncertainty",
        default=None,
        help="uncertainty set YAML for the robust verdicts (default: config/uncertainty.yaml)",
    )
    parser.add_argument(
        "--full-factorial", action="store_true", help="fly every corner of the set, not its resolution-IV design"
    )
    parser.add_argument(
        "--fly-all-models", action="store_true",
        help="fly every model of a node even after one fails (slower; the verdict is the same, the counts complete)",
    )  # fmt: skip


def register(subparsers: argparse._SubParsersAction) -> None:
    """Adds ``envelope`` with its ``compute``, ``robust``, ``query`` and ``plot`` subcommands."""
    parser = subparsers.add_parser(
        "envelope",
        help="H-V envelopes: compute, query, plot",
        description="Height-velocity envelopes: where a safe landing after an engine failure is reachable.",
    )
    commands = parser.add_subparsers(dest="envelope_command", required=True, metavar="SUBCOMMAND")

    compute = commands.add_parser(
        "compute",
        help="compute an envelope (or a sweep over weights, density altitudes and winds)",
        description="One verified landing plan per (height, speed) node, warm-started along columns, suspicious "
        "nodes re-solved cold, the boundary bisected to 2 ft / 1 kt. Ctrl-C saves a partial file; --resume "
        "continues it. With more than one --weights-lb/--density-altitude-ft/--headwinds-kt combination, --out is a "
        "folder holding one file per combination.",
    )
    compute.add_argument("--airframe", default="uh60a_class", help="airframe name or YAML path (default: %(default)s)")
    add_rotor_model_option(compute)
    compute.add_argument("--settings", default=None, help="planner settings YAML (default: config/planner.yaml)")
    compute.add_argument("--heights-ft", default="0:800:41", help="start:stop:count, inclusive (default: %(default)s)")
    compute.add_argument("--speeds-kt", default="0:120:25", help="start:stop:count, inclusive (default: %(default)s)")
    compute.add_argument(
        "--power-fraction", type=float, default=0.0, help="engine power left, fraction of trim (default: 0)"
    )
    compute.add_argument(
        "--climb-rates-fpm",
        default=None,
        help="comma-separated climb rates, ft/min, positive up (e.g. -2000,-1000,0,1500; write --climb-rates-fpm=-2000,"
        "... when the list starts with a minus): a 3-D envelope with one slice per rate (default: 2-D, level trim)",
    )
    compute.add_argument(
        "--method", choices=METHODS, default=None, help="override the settings file's transcription method"
    )
    compute.add_argument(
        "--reaction-delay-s", type=float, default=None, help="override the settings file's reaction delay, s"
    )
    compute.add_argument("--weights-lb", default=None, help="comma-separated gross weights, lbf (sweep)")
    compute.add_argument("--density-altitude-ft", default=None, help="comma-separated density altitudes, ft (sweep)")
    compute.add_argument(
        "--headwinds-kt",
        default=None,
        help="comma-separated steady winds along the track, kt, positive against the flight (sweep; write "
        "--headwinds-kt=-15,0,15 when the list starts with a minus): an H-V diagram per wind, as the status node "
        "needs for the planner parameter headwind",
    )
    compute.add_argument(
        "--refine-levels", type=int, default=0, metavar="L",
        help="boundary-following refinement over L levels (default 0: the full grid): every 2^L-th node first, "
        "then per level only the cells whose corners disagree get the full procedure; a safe cell's inside one warm "
        "solve per node (kept only if its plan is replay-verified), an unsafe cell's inside none (stored unsafe). "
        "Needs 2^L k + 1 heights and speeds (e.g. --heights-ft 0:800:81 --speeds-kt 0:120:49 with L up to 4)",
    )  # fmt: skip
    _add_executor_arguments(compute)
    compute.add_argument("--out", required=True, help="output .npz (a folder for a sweep of several combinations)")
    compute.add_argument("--resume", action="store_true", help="continue the partial file(s) at --out")
    compute.add_argument("--quiet", action="store_true", help="no progress output")
    compute.add_argument(
        "--robust", action="store_true",
        help="also store a robust verdict per node: each safe level-trim node's landing flown closed loop through "
        "the uncertainty set's corners (see 'helireach envelope robust')",
    )  # fmt: skip
    _add_robust_arguments(compute)
    compute.set_defaults(handler=_compute)

    robust = commands.add_parser(
        "robust",
        help="add robust verdicts to an envelope: does each safe node still land when the model is wrong?",
        description="For every safe node of the file's level-trim slice, fly its landing through the models of "
        "the uncertainty set's design, closed loop with the planner node's re-planning policy and each model's "
        "latency (and open loop, reported): 'robust' when every closed loop lands within the true limits. "
        "Writes a copy of the file with the verdicts; the nominal envelope is unchanged.",
    )
    robust.add_argument("file", help="a complete envelope .npz")
    robust.add_argument("--out", required=True, help="output .npz (may be the input file)")
    robust.add_argument("--airframe", default="uh60a_class", help="the file's airframe (checked; default: %(default)s)")
    robust.add_argument("--settings", default=None, help="the file's planner settings YAML (checked)")
    _add_executor_arguments(robust)
    _add_robust_arguments(robust)
    robust.add_argument("--quiet", action="store_true", help="no progress output")
    robust.set_defaults(handler=_robust)

    family = commands.add_parser(
        "family",
        help="an envelope family: the conditions it holds for, its members, where they are not monotone",
        description="Checks every member (complete, unaltered, one grid of weights x density altitudes) and prints "
        "the range the family answers for, each member's statuses, and the grid nodes where a heavier or higher "
        "member is safe and its lighter or lower neighbour is not (there the worst of the neighbours is no bound "
        "between them). Exit 0, or 2 for a family that does not load.",
    )
    family.add_argument("folder", help="the family's folder (or its family.json)")
    family.add_argument("--json", action="store_true", help="print JSON")
    family.set_defaults(handler=_family)

    query = commands.add_parser(
        "query",
        help="status, value and margin at a height and speed",
        description="Exit code 0 only when the point is safe (replay-verified at every enclosing node); 1 when it "
        "is not safe (unsafe, unverified, failed or outside the grid); 2 for bad input (unreadable or mismatched "
        "file, non-finite height or speed).",
    )
    query.add_argument("file", help="envelope .npz, or an envelope family (its folder or family.json)")
    query.add_argument("--height-ft", type=float, required=True)
    query.add_argument("--speed-kt", type=float, required=True)
    query.add_argument("--climb-rate-fpm", type=float, default=0.0, help="ft/min, positive up (default: 0, level)")
    query.add_argument("--airframe", default=None, help="refuse the file unless it is for this airframe")
    query.add_argument(
        "--verdict", choices=("nominal", "robust"), default="nominal",
        help="robust: the robust verdict where the file has one (a safe node that is not robust: not_robust)",
    )  # fmt: skip
    query.add_argument("--json", action="store_true", help="print JSON (status, value, margin, ...)")
    query.add_argument(
        "--weight-lb", type=float, default=None,
        help="a family: the gross weight, lbf (between members: the worst of the neighbouring members)",
    )  # fmt: skip
    query.add_argument("--density-altitude-ft", type=float, default=None, help="a family: the density altitude, ft")
    query.add_argument("--headwind-kt", type=float, default=0.0, help="a family: the headwind, kt (default: calm)")
    query.set_defaults(handler=_query)

    plot = commands.add_parser(
        "plot",
        help="the flight-manual H-V diagram as an image; several files: their boundaries overlaid",
        description="One file: its H-V diagram (a 3-D file: the slice nearest --climb-rate-fpm, or every slice with "
        "--all-slices). Several files: their boundaries in one figure, each labelled from its metadata.",
    )
    plot.add_argument(
        "files", nargs="+", metavar="file", help="envelope .npz or family folder (several, or a family: overlay)"
    )
    plot.add_argument("--out", required=True, help="image file (.png, .svg, .pdf)")
    plot.add_argument("--title", default=None, help="extra title text")
    plot.add_argument(
        "--climb-rate-fpm",
        type=float,
        default=None,
        help="3-D files: draw the slice nearest this climb rate (default 0)",
    )
    plot.add_argument("--all-slices", action="store_true", help="3-D file: one panel per climb slice")
    plot.set_defaults(handler=_plot)


def _error(message: str) -> int:
    print(f"helireach envelope: error: {message}", file=sys.stderr)
    return 2


def _compute(arguments: argparse.Namespace) -> int:
    from helireach_ros.core.aircraft.airframe import ConfigError, load_airframe
    from helireach_ros.core.envelope.compute import ComputeInterrupted, EnvelopeJob, compute_envelopes
    from helireach_ros.core.envelope.data import STATUS_CODES, EnvelopeError, save_envelope
    from helireach_ros.core.envelope.grid import condition_file_name, parse_list, parse_range
    from helireach_ros.core.envelope.progress import Progress
    from helireach_ros.core.envelope.workers import make_executor
    from helireach_ros.core.ocp.settings import load_settings
    from helireach_ros.core.robustness.envelope_verdicts import add_robust_verdicts
    from helireach_ros.core.units import FT, KT, LBF

    try:
        airframe = load_airframe(arguments.airframe).with_rotor_model_choice(arguments.rotor_model)
        settings = load_settings(arguments.settings)
        overrides = {
            name: value
            for name, value in (("method", arguments.method), ("reaction_delay_s", arguments.reaction_delay_s))
            if value is not None
        }
        settings = settings.replace(**overrides) if overrides else settings
        climb_rates = _climb_axis(arguments.climb_rates_fpm, FT / 60.0)
        heights = parse_range(arguments.heights_ft, FT, "--heights-ft")
        speeds = parse_range(arguments.speeds_kt, KT, "--speeds-kt")
        weights = parse_list(arguments.weights_lb, "--weights-lb") if arguments.weights_lb else [None]
        altitudes = (
            parse_list(arguments.density_altitude_ft, "--density-altitude-ft")
            if arguments.density_altitude_ft
            else [None]
        )
        winds = parse_list(arguments.headwinds_kt, "--headwinds-kt") if arguments.headwinds_kt else [None]
        airframes = [
            airframe.with_conditions(
                gross_weight=None if weight is None else weight * LBF,
                density_altitude=None if altitude is None else altitude * FT,
                headwind=None if wind is None else wind * KT,
            )
            for weight in weights
            for altitude in altitudes
            for wind in winds
        ]
        jobs = [
            EnvelopeJob(
                a,
                settings,
                arguments.power_fraction,
                heights,
                speeds,
                climb_rates=climb_rates,
                refine_levels=arguments.refine_levels,
            )
            for a in airframes
        ]
        robust_job = _robust_job_factory(arguments) if arguments.robust else None
    except (ConfigError, ValueError) as error:
        return _error(str(error))
    out = Path(arguments.out)
    if len(jobs) == 1 and not out.is_dir():
        paths = [out]
    else:
        paths = [out / condition_file_name(job.airframe, job.power_fraction) for job in jobs]
    for path in paths:
        if path.exists() and not arguments.resume and _is_partial(path):
            return _error(f"{path} is a partial envelope; continue it with --resume, or delete it to start over")
    command = "helireach " + shlex.join(sys.argv[1:]) if sys.argv[1:2] == ["envelope"] else None
    grid_spec = {"heights_ft": arguments.heights_ft, "speeds_kt": arguments.speeds_kt}
    if climb_rates is not None:
        grid_spec["climb_rates_fpm"] = arguments.climb_rates_fpm
    slices = f"{len(climb_rates)} climb rates x " if climb_rates is not None else ""
    try:
        executor = make_executor(arguments.workers, arguments.scheduler, arguments.dask_local)
    except (ValueError, OSError) as error:
        return _error(f"cannot start the workers: {error}")
    family = None
    if not (len(paths) == 1 and paths[0] == out):  # a sweep into a folder: the family index beside its members
        from helireach_ros.core.envelope.family import FamilyIndexWriter, FamilyMember

        members = [
            FamilyMember(
                file=path.name, gross_weight=job.airframe.gross_weight, density_altitude=job.airframe.density_altitude,
                headwind=job.airframe.headwind, power_fraction=job.power_fraction,
            )
            for job, path in zip(jobs, paths, strict=True)
        ]  # fmt: skip
        family = FamilyIndexWriter(out, jobs[0].airframe.name, members, command)
    progress = None if arguments.quiet else Progress(sys.stderr)
    for index, (job, path) in enumerate(zip(jobs, paths, strict=True)):
        if progress:
            label = f"[{index + 1}/{len(jobs)}] " if len(jobs) > 1 else ""
            progress.message(
                f"{label}{job.airframe.name}, W = {job.airframe.gross_weight / LBF:.0f} lbf, density altitude "
                f"{job.airframe.density_altitude / FT:.0f} ft, headwind {job.airframe.headwind / KT:+.0f} kt, "
                f"power fraction {job.power_fraction:g}: "
                f"{slices}{len(heights)} x {len(speeds)} nodes, method {job.settings.method}, reaction delay "
                f"{job.settings.reaction_delay_s:g} s, on {executor.description} -> {path}"
            )
    if progress and len(jobs) > 1:
        progress.message(f"{len(jobs)} envelopes computed together: every phase runs all of their tasks")
    try:
        envelopes = compute_envelopes(
            jobs, executor, paths, resume=[arguments.resume and path.exists() for path in paths], progress=progress,
            command=command, grid_spec=grid_spec,
        )  # fmt: skip
        for index, (job, path, envelope) in enumerate(zip(jobs, paths, envelopes, strict=True)):
            if robust_job is not None:
                envelope = add_robust_verdicts(
                    envelope, robust_job(job.airframe, job.settings), executor, progress, command
                )
                save_envelope(envelope, path)
                _print_robust(path, envelope)
            if family is not None:
                family.completed(index, envelope.envelope_id)
            counts = {name: int((envelope.status == name).sum()) for name in STATUS_CODES}
            compute = envelope.metadata.get("compute", {})
            print(
                f"{path}: envelope {envelope.envelope_id}: {counts}, {len(envelope.boundary)} boundary points, "
                f"{compute.get('wall_time_s', float('nan')):.1f} s"
            )
    except ComputeInterrupted as interrupted:
        print(f"interrupted: partial envelope saved to {interrupted.path}; continue with --resume", file=sys.stderr)
        return 130
    except EnvelopeError as error:
        return _error(str(error))
    except Exception as error:  # a worker or cluster failure: say what happened, keep the partial file
        return _error(f"computation failed ({type(error).__name__}: {error}); a partial file (if any) can be resumed")
    finally:
        executor.close()
    return 0


def _robust_job_factory(arguments: argparse.Namespace):
    """A function (airframe, settings) -> RobustEnvelopeJob for the robust arguments.

    Raises:
        ConfigError, ValueError: an unreadable uncertainty set.
    """
    from helireach_ros.core.flight.uncertainty import DEFAULT_UNCERTAINTY_FILE, load_uncertainty_set
    from helireach_ros.core.robustness.envelope_verdicts import RobustEnvelopeJob

    uncertainty = load_uncertainty_set(arguments.uncertainty or DEFAULT_UNCERTAINTY_FILE)

    def job(airframe, settings) -> RobustEnvelopeJob:
        return RobustEnvelopeJob(
            airframe, settings, uncertainty, stop_at_first_failure=not arguments.fly_all_models,
            full_factorial=arguments.full_factorial,
        )  # fmt: skip

    return job


def _print_robust(path: Path, envelope) -> None:
    robust = envelope.metadata["robust"]
    cost = robust["cost"]
    print(
        f"{path}: robust verdicts ({robust['design']}): {robust['counts']}; {cost['nodes_flown']} nodes flown in "
        f"{cost['wall_time_s']:.0f} s on {cost['executor']} ({cost['seconds_per_node_mean'] or 0:.1f} s per node, "
        f"{cost['plans_solved']} plans solved); of the not robust nodes, the first failing model has no safe "
        f"landing of its own at {robust['not_robust_failing_model_has_no_landing']}, has one at "
        f"{robust['not_robust_failing_model_has_a_landing']}"
    )


def _robust(arguments: argparse.Namespace) -> int:
    """``envelope robust``: robust verdicts for an existing envelope."""
    from helireach_ros.core.aircraft.airframe import ConfigError, load_airframe
    from helireach_ros.core.envelope.data import EnvelopeError, load_envelope, save_envelope
    from helireach_ros.core.envelope.progress import Progress
    from helireach_ros.core.envelope.workers import make_executor
    from helireach_ros.core.ocp.settings import load_settings
    from helireach_ros.core.robustness.envelope_verdicts import add_robust_verdicts

    try:
        airframe = load_airframe(arguments.airframe)
        settings = load_settings(arguments.settings)
        envelope = load_envelope(arguments.file, airframe=airframe)
        job = _robust_job_factory(arguments)(airframe, settings)
        envelope.check_matches(settings=settings, where=f"envelope file {arguments.file!r}")
    except (ConfigError, ValueError) as error:  # EnvelopeError is a ValueError
        return _error(str(error))
    try:
        executor = make_executor(arguments.workers, arguments.scheduler, arguments.dask_local)
    except (ValueError, OSError) as error:
        return _error(f"cannot start the workers: {error}")
    progress = None if arguments.quiet else Progress(sys.stderr)
    command = "helireach " + shlex.join(sys.argv[1:]) if sys.argv[1:2] == ["envelope"] else None
    try:
        envelope = add_robust_verdicts(envelope, job, executor, progress, command)
    except EnvelopeError as error:
        return _error(str(error))
    except KeyboardInterrupt:
        executor.abort()
        print("interrupted: no file written", file=sys.stderr)
        return 130
    except Exception as error:  # a worker or cluster failure
        executor.abort()
        return _error(f"robust verification failed ({type(error).__name__}: {error})")
    finally:
        executor.close()
    path = save_envelope(envelope, arguments.out)
    _print_robust(path, envelope)
    return 0


def _climb_axis(text: str | None, unit: float) -> tuple[float, ...] | None:
    """``--climb-rates-fpm``: ascending SI climb rates, None without the flag.

    Raises:
        ValueError: not numbers, or a rate given twice.
    """
    from helireach_ros.core.envelope.grid import parse_list

    if text is None:
        return None
    rates = sorted(parse_list(text, "--climb-rates-fpm"))
    if len(set(rates)) != len(rates):
        raise ValueError(f"--climb-rates-fpm lists a climb rate twice: {text!r}")
    return tuple(rate * unit for rate in rates)


def _is_partial(path: Path) -> bool:
    from helireach_ros.core.envelope.data import EnvelopeError, read_envelope_file

    try:
        return not read_envelope_file(path, allow_partial=True).complete
    except EnvelopeError:
        return False  # unreadable: nothing to resume, overwrite it


def _query(arguments: argparse.Namespace) -> int:
    """Exit code 0 safe, 1 not safe (like ``helireach plan``), 2 bad input."""
    from helireach_ros.core.envelope.data import EnvelopeError
    from helireach_ros.core.units import FT, KT

    given = (arguments.height_ft, arguments.speed_kt, arguments.climb_rate_fpm)
    if not all(math.isfinite(value) for value in given):
        return _error(f"--height-ft, --speed-kt and --climb-rate-fpm must be finite, got {', '.join(map(str, given))}")
    try:
        airframe = None
        if arguments.airframe:
            from helireach_ros.core.aircraft.airframe import ConfigError, load_airframe

            try:
                airframe = load_airframe(arguments.airframe)
            except ConfigError as error:
                return _error(str(error))
        envelope = _envelope_or_family_member(arguments, airframe)
    except EnvelopeError as error:
        return _error(str(error))
    answer = envelope.query(
        arguments.height_ft * FT, arguments.speed_kt * KT, arguments.climb_rate_fpm * FT / 60.0, arguments.verdict
    )
    if arguments.json:
        document = answer.to_dict() | {
            "height_ft": arguments.height_ft,
            "speed_kt": arguments.speed_kt,
            "climb_rate_fpm": arguments.climb_rate_fpm,
            "margin_units": "ft/kt",
            "envelope_id": envelope.envelope_id,
            "airframe": envelope.airframe_name,
            "power_fraction": envelope.power_fraction,
        }
        document["conditions"] = envelope.conditions
        print(json.dumps(document))
    else:
        print(
            f"{arguments.height_ft:g} ft, {arguments.speed_kt:g} kt, {arguments.climb_rate_fpm:+g} ft/min: "
            f"{answer.status} ({answer.verdict} verdict, value {answer.value:.3f}, "
            f"margin {answer.margin:.1f} ft/kt) [{envelope.airframe_name}, envelope {envelope.envelope_id}, "
            f"{envelope.conditions}]"
        )
    return 0 if answer.status == "safe" else 1  # unsafe, not_robust, unverified, failed, outside: all "not safe"


def _family(arguments: argparse.Namespace) -> int:
    from helireach_ros.core.envelope.data import STATUS_CODES, EnvelopeError
    from helireach_ros.core.envelope.family import EnvelopeFamily

    try:
        family = EnvelopeFamily.load(arguments.folder)
    except EnvelopeError as error:
        return _error(str(error))
    members = [
        {
            "file": member.file, "conditions": member.conditions, "envelope_id": envelope.envelope_id,
            "statuses": {name: int((envelope.status == name).sum()) for name in STATUS_CODES},
        }
        for member, envelope in family.members
    ]  # fmt: skip
    exceptions = family.monotonicity_exceptions()
    if arguments.json:
        print(json.dumps({
            "airframe": family.airframe_name, "range": family.range_text(), "members": members,
            "monotonicity_exceptions": exceptions, "valid_up_to": family.valid_up_to(),
        }))  # fmt: skip
        return 0
    print(f"{family.airframe_name} envelope family: answers for {family.range_text()} ({len(members)} members)")
    for member in members:
        print(f"  {member['conditions']:32} {member['file']}: {member['statuses']}")
    for line in family.valid_up_to():
        print(f"  {line}")
    print(f"  not monotone in weight or density altitude at {len(exceptions)} grid nodes")
    for line in exceptions:
        print(f"    {line}")
    return 0


def _envelope_or_family_member(arguments: argparse.Namespace, airframe: Any) -> Any:
    """The file's envelope, or a family at ``--weight-lb``/``--density-altitude-ft``/``--headwind-kt``.

    Raises:
        EnvelopeError: an unreadable file or family, conditions missing for a family (or given for a single file), or
            outside the family's range.
    """
    from helireach_ros.core.envelope.data import EnvelopeError, load_envelope
    from helireach_ros.core.envelope.family import EnvelopeFamily, is_family
    from helireach_ros.core.units import FT, KT, LBF

    conditions = (arguments.weight_lb, arguments.density_altitude_ft)
    if not is_family(arguments.file):
        if any(value is not None for value in conditions):
            raise EnvelopeError("--weight-lb and --density-altitude-ft are for an envelope family; a file has its own")
        return load_envelope(arguments.file, airframe=airframe)
    if any(value is None or not math.isfinite(value) for value in conditions) or not math.isfinite(
        arguments.headwind_kt
    ):
        raise EnvelopeError("an envelope family needs finite --weight-lb and --density-altitude-ft")
    family = EnvelopeFamily.load(arguments.file, airframe)
    return family.at(arguments.weight_lb * LBF, arguments.density_altitude_ft * FT, arguments.headwind_kt * KT)


def _plot(arguments: argparse.Namespace) -> int:
    from helireach_ros.core.envelope.data import EnvelopeError, load_envelope
    from helireach_ros.core.envelope.family import EnvelopeFamily, is_family
    from helireach_ros.core.envelope.plot import plot_all_slices, plot_envelope, plot_overlay
    from helireach_ros.core.units import FT

    climb_rate = None if arguments.climb_rate_fpm is None else arguments.climb_rate_fpm * FT / 60.0
    if climb_rate is not None and not math.isfinite(climb_rate):
        return _error(f"--climb-rate-fpm must be finite, got {arguments.climb_rate_fpm}")
    envelopes, names = [], []
    try:
        for file in arguments.files:  # a family: every member, its boundary labelled by its conditions
            members = EnvelopeFamily.load(file).members if is_family(file) else [(None, load_envelope(file))]
            for member, envelope in members:
                envelopes.append(envelope)
                names.append(member.file if member is not None else Path(file).name)
    except EnvelopeError as error:
        return _error(str(error))
    if arguments.all_slices and (len(envelopes) > 1 or not envelopes[0].is_3d or climb_rate is not None):
        return _error("--all-slices draws every slice of one 3-D file (no --climb-rate-fpm)")
    try:
        if len(envelopes) > 1:
            path = plot_overlay(envelopes, arguments.out, names, climb_rate=climb_rate, title_extra=arguments.title)
        elif arguments.all_slices:
            path = plot_all_slices(envelopes[0], arguments.out, title_extra=arguments.title)
        else:
            path = plot_envelope(envelopes[0], arguments.out, title_extra=arguments.title, climb_rate=climb_rate)
    except (OSError, ValueError) as error:
        return _error(f"cannot write {arguments.out}: {error}")
    print(path)
    return 0
