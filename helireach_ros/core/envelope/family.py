"""Envelope families: one airframe's H-V diagrams over gross weight and density altitude, answered as one product.

A flight manual states the conditions its H-V diagram holds for (gross weight, density altitude). A family is what
``helireach envelope compute --weights-lb … --density-altitude-ft … --out FOLDER`` writes: one envelope per
combination and the index ``family.json`` (:data:`FAMILY_INDEX`: every member's conditions, file, SHA-256 and
whether it is complete), rewritten when the members complete; the members are computed together
(:func:`~helireach_ros.core.envelope.compute.compute_envelopes`), so ``--resume`` continues the family as a whole.

At a member's conditions the family answers exactly as that member. Between members it answers from the
neighbouring members, the two or four whose weights and density altitudes bracket the conditions, and takes the
worst of them:

.. math:: s(x; W, \\rho) = \\bigwedge_{m \\in N(W, \\rho)} s_m(x), \\qquad
    \\text{margin} = \\min_{m} \\text{margin}_m(x), \\qquad V = \\max_{m} V_m(x)

(safe only if every neighbour is safe there). That bounds the answer between members only as far as the avoid
region grows with weight and density altitude, as published H-V diagrams' do (FAA, Helicopter Flying Handbook,
FAA-H-8083-21B, ch. 11: the height-velocity diagram is drawn for a gross weight and density altitude, and the
avoid region grows with both); :meth:`EnvelopeFamily.monotonicity_exceptions` lists the grid nodes where the
members themselves say otherwise. Outside the family's range it answers ``outside`` and says why: never the
nearest member.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
import os
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from helireach_ros.core.aircraft.airframe import Airframe
from helireach_ros.core.envelope.data import Envelope, EnvelopeError, EnvelopeQuery, load_envelope
from helireach_ros.core.units import FT, KT, LBF

__all__ = [
    "FAMILY_INDEX",
    "ConditionedEnvelope",
    "EnvelopeFamily",
    "FamilyIndexWriter",
    "FamilyMember",
    "family_member_path",
    "file_sha256",
    "is_family",
    "read_family_index",
    "write_family_index",
]

FAMILY_INDEX = "family.json"
_FORMAT = "helireach_envelope_family"
_FORMAT_VERSION = 1
_WEIGHT_TOLERANCE = 0.5  # N: conditions this close to a member's are that member's
_ALTITUDE_TOLERANCE = 0.5  # m
_WIND_TOLERANCE = 0.05  # m/s
_MAX_VIEWS = 64  # conditions whose view is kept (a status node asks again at the same ones)
_STATUS_RANK = {"safe": 0}  # every other status is "not safe"; among those the smaller margin is the worse


@dataclass(frozen=True)
class FamilyMember:
    """One envelope of a family.

    Attributes:
        file: the envelope's file name, in the index's folder.
        gross_weight: N. density_altitude: m. headwind: m/s (positive against the flight).
        power_fraction: the envelope's engine power fraction.
        complete: the member's computation finished (its file is final).
        sha256: of the complete file ("" before).
        envelope_id: the complete envelope's id ("" before).
    """

    file: str
    gross_weight: float
    density_altitude: float
    headwind: float = 0.0
    power_fraction: float = 0.0
    complete: bool = False
    sha256: str = ""
    envelope_id: str = ""

    @property
    def conditions(self) -> str:
        """``16000 lbf, DA 0 ft`` (and the wind when there is one)."""
        wind = f", headwind {self.headwind / KT:+.0f} kt" if self.headwind else ""
        return f"{self.gross_weight / LBF:.0f} lbf, DA {self.density_altitude / FT:.0f} ft{wind}"

    def to_dict(self) -> dict[str, Any]:
        return {
            "file": self.file, "gross_weight_n": self.gross_weight, "density_altitude_m": self.density_altitude,
            "headwind_m_s": self.headwind, "power_fraction": self.power_fraction, "complete": self.complete,
            "sha256": self.sha256, "envelope_id": self.envelope_id,
        }  # fmt: skip

    @classmethod
    def from_dict(cls, document: dict[str, Any]) -> FamilyMember:
        try:
            return cls(
                file=str(document["file"]),
                gross_weight=float(document["gross_weight_n"]),
                density_altitude=float(document["density_altitude_m"]),
                headwind=float(document.get("headwind_m_s", 0.0)),
                power_fraction=float(document.get("power_fraction", 0.0)),
                complete=bool(document.get("complete", False)),
                sha256=str(document.get("sha256", "")),
                envelope_id=str(document.get("envelope_id", "")),
            )
        except (KeyError, TypeError, ValueError) as error:
            raise EnvelopeError(f"family member {document!r} is malformed ({error})") from None


def file_sha256(path: str | os.PathLike[str]) -> str:
    """SHA-256 of a file's bytes."""
    digest = hashlib.sha256()
    with open(path, "rb") as stream:
        for block in iter(lambda: stream.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def _index_path(path: str | os.PathLike[str]) -> Path:
    location = Path(path)
    return location / FAMILY_INDEX if location.is_dir() else location


def is_family(path: str | os.PathLike[str]) -> bool:
    """Whether ``path`` is a family: its index, or a folder holding one."""
    location = Path(path)
    return (location.is_dir() and (location / FAMILY_INDEX).is_file()) or location.name == FAMILY_INDEX


def write_family_index(
    folder: str | os.PathLike[str], airframe_name: str, members: Sequence[FamilyMember], command: str | None = None
) -> Path:
    """Writes (atomically) the family index of ``folder``; returns its path."""
    path = Path(folder) / FAMILY_INDEX
    document = {
        "format": _FORMAT, "format_version": _FORMAT_VERSION, "airframe": airframe_name, "command": command,
        "members": [member.to_dict() for member in members],
    }  # fmt: skip
    temporary = path.with_name(f".{FAMILY_INDEX}.{os.getpid()}.tmp")
    temporary.write_text(json.dumps(document, indent=1) + "\n")
    os.replace(temporary, path)
    return path


class FamilyIndexWriter:
    """Keeps a sweep's family index: written before the members are computed, rewritten as each is recorded complete. A
    resumed sweep keeps the members the folder's index already lists as complete (their files untouched)."""

    def __init__(
        self, folder: str | os.PathLike[str], airframe_name: str, members: Sequence[FamilyMember], command: str | None
    ) -> None:
        self._folder, self._airframe_name, self._command = Path(folder), airframe_name, command
        self._folder.mkdir(parents=True, exist_ok=True)
        previous: dict[str, FamilyMember] = {}
        if (self._folder / FAMILY_INDEX).is_file():
            try:
                previous = {member.file: member for member in read_family_index(self._folder)[1]}
            except EnvelopeError:  # an unreadable index is rewritten from what the sweep knows
                previous = {}
        self.members = [
            previous[member.file]
            if member.file in previous and previous[member.file].complete and (self._folder / member.file).is_file()
            else member
            for member in members
        ]
        write_family_index(self._folder, airframe_name, self.members, command)

    def completed(self, index: int, envelope_id: str) -> None:
        """Records member ``index`` as complete (its file final: SHA-256 taken now) and rewrites the index."""
        member = self.members[index]
        self.members[index] = dataclasses.replace(
            member, complete=True, sha256=file_sha256(self._folder / member.file), envelope_id=envelope_id
        )
        write_family_index(self._folder, self._airframe_name, self.members, self._command)


def read_family_index(path: str | os.PathLike[str]) -> tuple[str, tuple[FamilyMember, ...], str | None]:
    """(airframe name, members, command) of a family index (its path or its folder).

    Raises:
        EnvelopeError: a missing, unreadable or malformed index.
    """
    index = _index_path(path)
    try:
        document = json.loads(index.read_text())
    except (OSError, ValueError) as error:
        raise EnvelopeError(f"cannot read envelope family index {str(index)!r}: {error}") from None
    if not isinstance(document, dict) or document.get("format") != _FORMAT:
        raise EnvelopeError(f"{str(index)!r} is not an envelope family index")
    if document.get("format_version") != _FORMAT_VERSION:
        raise EnvelopeError(f"{str(index)!r}: family format version {document.get('format_version')!r} is not 1")
    members = tuple(FamilyMember.from_dict(member) for member in document.get("members") or [])
    if not members:
        raise EnvelopeError(f"{str(index)!r} lists no members")
    return str(document.get("airframe", "")), members, document.get("command")


def family_member_path(path: str | os.PathLike[str], airframe: Airframe) -> Path | None:
    """The file of the family member made for exactly ``airframe``'s conditions (None when ``path`` is not a family).

    Raises:
        EnvelopeError: a family without a complete member for these conditions.
    """
    if not is_family(path):
        return None
    index = _index_path(path)
    _, members, _ = read_family_index(index)
    for member in members:
        if (
            member.complete
            and abs(member.gross_weight - airframe.gross_weight) <= _WEIGHT_TOLERANCE
            and abs(member.density_altitude - airframe.density_altitude) <= _ALTITUDE_TOLERANCE
            and abs(member.headwind - airframe.headwind) <= _WIND_TOLERANCE
        ):
            return index.parent / member.file
    raise EnvelopeError(
        f"envelope family {str(index.parent)!r} has no complete member for W = {airframe.gross_weight / LBF:.0f} lbf, "
        f"density altitude {airframe.density_altitude / FT:.0f} ft (its stored plans are only for its members' "
        "conditions)"
    )


def _bracket(value: float, axis: Sequence[float], tolerance: float) -> tuple[float, ...] | None:
    """The axis values that bracket ``value``: itself (within ``tolerance``), its two neighbours, or None outside."""
    for point in axis:
        if abs(value - point) <= tolerance:
            return (point,)
    below = [point for point in axis if point < value]
    above = [point for point in axis if point > value]
    if not below or not above:
        return None
    return max(below), min(above)


def _worst(answers: Iterable[EnvelopeQuery]) -> EnvelopeQuery:
    """The worst of the members' answers: safe only if all are; the smallest margin, the largest value."""
    listed = list(answers)
    worst = max(listed, key=lambda answer: (_STATUS_RANK.get(answer.status, 1), -_finite_or(answer.margin, -math.inf)))
    margins = [answer.margin for answer in listed]
    values = [answer.value for answer in listed]
    return EnvelopeQuery(
        status=worst.status,
        value=math.nan if any(math.isnan(value) for value in values) else max(values),
        margin=math.nan if any(math.isnan(margin) for margin in margins) else min(margins),
        by_interpolation=any(answer.by_interpolation for answer in listed),
        verdict="robust" if all(answer.verdict == "robust" for answer in listed) else "nominal",
    )


def _finite_or(number: float, default: float) -> float:
    return number if math.isfinite(number) else default


class ConditionedEnvelope:
    """The family at one set of conditions, answering as one envelope (what the status node holds).

    It has what :func:`~helireach_ros.core.policies.safety_status.assess_safety` reads of an envelope; its
    ``query`` is the worst of the neighbouring members' (:func:`_worst`).
    """

    def __init__(self, members: Sequence[tuple[FamilyMember, Envelope]], conditions: str) -> None:
        self.members = tuple(members)
        first = self.members[0][1]
        self.is_3d = first.is_3d
        self.power_fraction = first.power_fraction
        self.metadata = first.metadata
        self.validity_domain = first.validity_domain
        self.has_robust_verdict = all(envelope.has_robust_verdict for _, envelope in self.members)
        self.airframe_name = first.airframe_name
        self.envelope_id = "+".join(envelope.envelope_id for _, envelope in self.members)
        used = "; ".join(member.conditions for member, _ in self.members)
        self.conditions = (
            f"member at {used}" if len(self.members) == 1 else f"{conditions}: worst of the members at {used}"
        )

    def query(self, height: float, speed: float, climb_rate: float = 0.0, verdict: str = "nominal") -> EnvelopeQuery:
        """The worst of the members' answers at (height m, speed m/s, climb rate m/s)."""
        return _worst(envelope.query(height, speed, climb_rate, verdict) for _, envelope in self.members)

    def __repr__(self) -> str:
        return f"ConditionedEnvelope({self.airframe_name}, {self.conditions}, id={self.envelope_id})"


class EnvelopeFamily:
    """A complete family, every member loaded and checked (:meth:`load`)."""

    def __init__(self, airframe_name: str, members: Sequence[tuple[FamilyMember, Envelope]], where: str) -> None:
        self.airframe_name = airframe_name
        self.members = tuple(members)
        self.where = where
        self._views: dict[tuple[float, float, float], ConditionedEnvelope] = {}

    @classmethod
    def load(cls, path: str | os.PathLike[str], airframe: Airframe | None = None) -> EnvelopeFamily:
        """Loads every member of the family at ``path`` (its folder or index).

        Args:
            path: the family's folder or ``family.json``.
            airframe: if given, every member must have been made for it at the member's own conditions (weight,
                density altitude, wind): the digest of ``airframe.with_conditions(…)`` equals the member's.

        Raises:
            EnvelopeError: an unreadable index, a member not complete, missing, altered (SHA-256) or made for
                another airframe, members of different validity domains, or weights × density altitudes that do not
                form a full grid at some wind.
        """
        index = _index_path(path)
        airframe_name, members, _ = read_family_index(index)
        where = f"envelope family {str(index.parent)!r}"
        loaded = []
        for member in members:
            file = index.parent / member.file
            if not member.complete:
                raise EnvelopeError(
                    f"{where}: member {member.file} ({member.conditions}) is not complete; finish it with "
                    f"'helireach envelope compute ... --resume'"
                )
            if not file.is_file() or file_sha256(file) != member.sha256:
                raise EnvelopeError(f"{where}: member {member.file} is missing or not the file the index names")
            conditioned = None
            if airframe is not None:
                conditioned = airframe.with_conditions(
                    gross_weight=member.gross_weight, density_altitude=member.density_altitude,
                    headwind=member.headwind,
                )  # fmt: skip
            loaded.append((member, load_envelope(file, conditioned, power_fraction=member.power_fraction)))
        domains = {repr(envelope.validity_domain) for _, envelope in loaded}
        if len(domains) > 1:
            raise EnvelopeError(f"{where}: its members have different validity domains")
        family = cls(airframe_name, loaded, where)
        for wind in family.headwinds:
            at_wind = [member for member, _ in loaded if abs(member.headwind - wind) <= _WIND_TOLERANCE]
            if len(at_wind) != len(family.weights) * len(family.density_altitudes):
                raise EnvelopeError(
                    f"{where}: at headwind {wind / KT:+.0f} kt its members do not cover every weight x density "
                    "altitude combination"
                )
        return family

    @property
    def weights(self) -> tuple[float, ...]:
        """The members' gross weights, N, ascending."""
        return tuple(sorted({member.gross_weight for member, _ in self.members}))

    @property
    def density_altitudes(self) -> tuple[float, ...]:
        """The members' density altitudes, m, ascending."""
        return tuple(sorted({member.density_altitude for member, _ in self.members}))

    @property
    def headwinds(self) -> tuple[float, ...]:
        """The members' headwinds, m/s, ascending."""
        return tuple(sorted({member.headwind for member, _ in self.members}))

    def range_text(self) -> str:
        """``15000-17000 lbf, DA 0-4000 ft`` (and the winds when there are several or one that is not calm)."""
        weights, altitudes, winds = self.weights, self.density_altitudes, self.headwinds
        text = (
            f"{weights[0] / LBF:.0f}-{weights[-1] / LBF:.0f} lbf, "
            f"DA {altitudes[0] / FT:.0f}-{altitudes[-1] / FT:.0f} ft"
        )
        if winds != (0.0,):
            text += ", headwinds " + ", ".join(f"{wind / KT:+.0f}" for wind in winds) + " kt"
        return text

    def at(self, gross_weight: float, density_altitude: float, headwind: float = 0.0) -> ConditionedEnvelope:
        """The family at these conditions (N, m, m/s): the member there, or the worst of the neighbouring members.

        Raises:
            EnvelopeError: conditions outside the family's range (never the nearest member), saying which.
        """
        key = (round(gross_weight, 3), round(density_altitude, 3), round(headwind, 3))
        if key in self._views:
            return self._views[key]
        wanted = f"{gross_weight / LBF:.0f} lbf, DA {density_altitude / FT:.0f} ft" + (
            f", headwind {headwind / KT:+.0f} kt" if headwind else ""
        )
        winds = _bracket(headwind, self.headwinds, _WIND_TOLERANCE)
        weights = _bracket(gross_weight, self.weights, _WEIGHT_TOLERANCE)
        altitudes = _bracket(density_altitude, self.density_altitudes, _ALTITUDE_TOLERANCE)
        if winds is None or len(winds) != 1:
            raise EnvelopeError(f"{wanted}: the family has no member for this wind ({self.range_text()})")
        if weights is None or altitudes is None:
            raise EnvelopeError(f"{wanted} is outside the family's range ({self.range_text()})")
        chosen = [
            (member, envelope)
            for member, envelope in self.members
            if member.headwind == winds[0] and member.gross_weight in weights and member.density_altitude in altitudes
        ]
        view = ConditionedEnvelope(chosen, wanted)
        if len(self._views) >= _MAX_VIEWS:  # conditions that vary (an estimated weight) must not grow it for ever
            self._views.clear()
        self._views[key] = view
        return view

    def monotonicity_exceptions(self) -> list[str]:
        """Grid nodes where a heavier or higher member is safe and its lighter or lower neighbour is not (the worst of
        the neighbours then is not a bound between them); one line each."""
        exceptions = []
        by_conditions = {
            (member.headwind, member.gross_weight, member.density_altitude): (member, envelope)
            for member, envelope in self.members
        }
        weights, altitudes = self.weights, self.density_altitudes
        for (wind, weight, altitude), (member, envelope) in sorted(by_conditions.items()):
            neighbours = []
            if weight != weights[-1]:
                neighbours.append(by_conditions.get((wind, weights[weights.index(weight) + 1], altitude)))
            if altitude != altitudes[-1]:
                neighbours.append(by_conditions.get((wind, weight, altitudes[altitudes.index(altitude) + 1])))
            for neighbour in neighbours:
                if neighbour is None or neighbour[1].status.shape != envelope.status.shape:
                    continue
                worse = (neighbour[1].status == "safe") & (envelope.status != "safe")
                for index in zip(*worse.nonzero(), strict=True):
                    exceptions.append(
                        f"{neighbour[0].conditions} safe where {member.conditions} is {envelope.status[index]} "
                        f"(node {tuple(int(i) for i in index)})"
                    )
        return exceptions

    def valid_up_to(self) -> list[str]:
        """The flight manual's "H-V diagram valid up to weight W at density altitude D", per wind.

        A member's diagram is valid up to its conditions when it is safe nowhere that a member at or below its weight
        and density altitude (same wind, same grid) is not: it then bounds every lighter, lower condition of the
        family conservatively. Returned: one line per member with that property that no heavier or higher such
        member dominates, e.g. ``H-V valid up to 17000 lbf at DA 4000 ft``.
        """
        lines = []
        for wind in self.headwinds:
            members = [(member, envelope) for member, envelope in self.members if member.headwind == wind]

            def bounds(top: FamilyMember, diagram: Envelope, members: list = members) -> bool:
                return all(
                    envelope.status.shape == diagram.status.shape
                    and not np.any((diagram.status == "safe") & (envelope.status != "safe"))
                    for member, envelope in members
                    if member.gross_weight <= top.gross_weight and member.density_altitude <= top.density_altitude
                )

            valid = [member for member, envelope in members if bounds(member, envelope)]
            for member in valid:
                dominated = any(
                    other is not member
                    and other.gross_weight >= member.gross_weight
                    and other.density_altitude >= member.density_altitude
                    for other in valid
                )
                if not dominated:
                    weight, altitude = member.gross_weight / LBF, member.density_altitude / FT
                    wind_text = f", headwind {wind / KT:+.0f} kt" if wind else ""
                    lines.append(f"H-V valid up to {weight:.0f} lbf at DA {altitude:.0f} ft{wind_text}")
        return lines

    def __repr__(self) -> str:
        return f"EnvelopeFamily({self.airframe_name}, {len(self.members)} members, {self.range_text()})"
