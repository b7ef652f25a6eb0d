"""The input contract of a stamped input: the frames it must be in, and stamps that only move forward.

One :class:`InputGate` per input topic (the monitor has one for ``/vehicle/odometry`` and one for
``/vehicle/rotor``). For each message it decides, in this order:

1. **wrong frame** → *rejected*: ``header.frame_id`` (and, where the contract names one, ``child_frame_id``)
   must equal the documented frame exactly (``odom`` / ``base_stabilized`` by default). A state in another
   frame (``map_ned``, ``base_link_frd``) means other axes and signs: reading it as ours would be wrong, not
   merely noisy, so it is never used. The reason names the received and the expected frame.
2. **invalid values** (NaN, range, stale stamp: found by the caller) → *rejected*.
3. **out of order** → *dropped*: a message whose stamp is not newer than the latest *accepted* stamp of the
   same input. Equal stamps are dropped too (a repeat of a measurement already used, or a second source
   claiming the same instant: the first one wins), so the accepted stamps are strictly increasing and the
   published state never goes backwards. Rejected messages never advance the latest stamp.

Otherwise the message is *accepted* and its stamp becomes the latest. If the receiving clock itself jumps
backwards (simulated time restarted, a replayed log looping with ``use_sim_time``) the order is reset, since
the stamps of the new run are then legitimately older. Every outcome is counted per reason.
"""

from __future__ import annotations

from dataclasses import dataclass, field

__all__ = [
    "ACCEPTED",
    "INVALID",
    "OUT_OF_ORDER",
    "REASONS",
    "WRONG_FRAME",
    "FrameContract",
    "InputGate",
    "InputVerdict",
    "StampOrder",
    "frame_problems",
]

ACCEPTED = "accepted"
WRONG_FRAME = "wrong_frame"
INVALID = "invalid"
OUT_OF_ORDER = "out_of_order"
REASONS = (ACCEPTED, WRONG_FRAME, INVALID, OUT_OF_ORDER)
"""Every outcome of :meth:`InputGate.judge` (the keys of :attr:`InputGate.counts`)."""


@dataclass(frozen=True)
class FrameContract:
    """The frame ids one input must carry; None = that field is not checked (e.g. a ``JointState``)."""

    frame_id: str | None = None
    child_frame_id: str | None = None


def frame_problems(contract: FrameContract, frame_id: str, child_frame_id: str = "") -> list[str]:
    """Why a message's frames break the contract (empty: they match exactly; case and '/' matter)."""
    problems = []
    for field_name, expected, received in (
        ("frame_id", contract.frame_id, frame_id),
        ("child_frame_id", contract.child_frame_id, child_frame_id),
    ):
        if expected is not None and received != expected:
            problems.append(f"{field_name} {received!r} is not the expected {expected!r}")
    return problems


class StampOrder:
    """The latest accepted stamp of one input; a stamp must be strictly newer to be accepted."""

    def __init__(self) -> None:
        self.latest_ns: int | None = None
        self._received_ns: int | None = None

    def problem(self, stamp_ns: int, received_ns: int) -> str:
        """Why ``stamp_ns`` (received at ``received_ns`` on the local clock) is out of order ('' if it is not).

        A receiving clock that went backwards since the latest accepted message resets the order first.
        """
        if self._received_ns is not None and received_ns < self._received_ns:
            self.latest_ns = self._received_ns = None
        if self.latest_ns is None or stamp_ns > self.latest_ns:
            return ""
        if stamp_ns == self.latest_ns:
            return f"stamp {_seconds(stamp_ns)} equals the latest accepted one (a repeat)"
        return (
            f"stamp {_seconds(stamp_ns)} is {(self.latest_ns - stamp_ns) * 1e-9:.3f} s older than the latest "
            f"accepted {_seconds(self.latest_ns)}"
        )

    def accept(self, stamp_ns: int, received_ns: int) -> None:
        """Makes ``stamp_ns`` the latest accepted stamp."""
        self.latest_ns, self._received_ns = stamp_ns, received_ns


def _seconds(stamp_ns: int) -> str:
    return f"{stamp_ns * 1e-9:.6f} s"


@dataclass(frozen=True)
class InputVerdict:
    """What happens to one message: ``reason`` is one of :data:`REASONS`; ``problems`` say why (if not accepted)."""

    reason: str
    problems: tuple[str, ...] = ()

    @property
    def accepted(self) -> bool:
        """The message may be used."""
        return self.reason == ACCEPTED

    @property
    def text(self) -> str:
        """The problems as one line ('' when accepted)."""
        return "; ".join(self.problems)


@dataclass
class InputGate:
    """The contract of one stamped input: frames, stamp order, and a count per outcome (see the module doc)."""

    frames: FrameContract = field(default_factory=FrameContract)
    order: StampOrder = field(default_factory=StampOrder)
    counts: dict[str, int] = field(default_factory=lambda: dict.fromkeys(REASONS, 0))

    def judge(
        self,
        stamp_ns: int,
        received_ns: int,
        frame_id: str = "",
        child_frame_id: str = "",
        value_problems: tuple[str, ...] | list[str] = (),
    ) -> InputVerdict:
        """Decides on one message (and counts it); an accepted stamp becomes the latest.

        Args:
            stamp_ns: the message's header stamp. received_ns: the local clock when it arrived.
            frame_id, child_frame_id: the message's frames (ignored where the contract names none).
            value_problems: what the caller found wrong with its values (NaN, range, age).
        """
        wrong_frames = frame_problems(self.frames, frame_id, child_frame_id)
        if wrong_frames:
            verdict = InputVerdict(WRONG_FRAME, tuple(wrong_frames))
        elif value_problems:
            verdict = InputVerdict(INVALID, tuple(value_problems))
        else:
            late = self.order.problem(stamp_ns, received_ns)
            verdict = InputVerdict(OUT_OF_ORDER, (late,)) if late else InputVerdict(ACCEPTED)
        if verdict.accepted:
            self.order.accept(stamp_ns, received_ns)
        self.counts[verdict.reason] += 1
        return verdict
