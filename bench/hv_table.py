"""The shape of H-V diagrams, one row per envelope file: what each planning setting does to the avoid regions.

Run: .venv/bin/python bench/hv_table.py A.npz B.npz ...   (3-D files: the level-flight slice)

Per file (computed with ``helireach envelope compute``; the command is in each file's metadata):

* safe: nodes called safe (replay-verified) of all nodes; unsafe share: the rest, in per cent;
* hover band: the lowest and highest not-safe heights at 0 kt above the ground row (ft);
* knee: the low-speed avoid region is the 4-connected set of not-safe nodes that holds the hover band's top;
  its knee is the largest speed at which that region still reaches half the band's top height (kt, at ft);
* not safe at the top speed: the not-safe heights in the fastest column (a low-level band at speed);
* separate high-speed region: not-safe nodes above the ground row, faster than the knee, that are *not* part of
  the low-speed region (the flight-manual shape: an avoid region at low height and high speed of its own).
"""

from __future__ import annotations

import argparse
from collections import deque

import numpy as np
from _common import command_line, loadavg_text

from helireach_ros.core.envelope.data import read_envelope_file
from helireach_ros.core.units import FT, KT


def _component(not_safe: np.ndarray, seed: tuple[int, int]) -> np.ndarray:
    """The 4-connected not-safe nodes holding ``seed`` (a boolean mask)."""
    region = np.zeros_like(not_safe)
    queue = deque([seed])
    region[seed] = True
    while queue:
        row, column = queue.popleft()
        for step_row, step_column in ((1, 0), (-1, 0), (0, 1), (0, -1)):
            neighbour = (row + step_row, column + step_column)
            if 0 <= neighbour[0] < not_safe.shape[0] and 0 <= neighbour[1] < not_safe.shape[1]:
                if not_safe[neighbour] and not region[neighbour]:
                    region[neighbour] = True
                    queue.append(neighbour)
    return region


def shape_row(path: str) -> dict[str, str]:
    """The table's columns for one envelope file."""
    envelope = read_envelope_file(path)
    if envelope.is_3d:
        envelope = envelope.slice(envelope.nearest_slice(0.0))
    metadata = envelope.metadata
    settings = metadata.get("settings", {})
    heights_ft, speeds_kt = envelope.heights / FT, envelope.speeds / KT
    not_safe = np.asarray(envelope.status) != "safe"
    not_safe[0, :] = False  # the ground row: on the ground already
    label = (
        f"{envelope.airframe_name}, {envelope.rotor_model_text}, {settings.get('method', metadata.get('method'))}, "
        f"delay {settings.get('reaction_delay_s', 0.0):g} s"
    )
    row = {"file": path, "setting": label, "safe": f"{int(np.sum(~not_safe[1:]))}/{not_safe[1:].size}",
           "unsafe share": f"{100.0 * not_safe[1:].mean():.1f} %"}  # fmt: skip
    hover = np.flatnonzero(not_safe[:, 0])
    if hover.size == 0:
        return {**row, "hover band": "none", "knee": "none", "top speed": "-", "separate high-speed region": "none"}
    row["hover band"] = f"{heights_ft[hover[0]]:.0f}-{heights_ft[hover[-1]]:.0f} ft"
    low_speed = _component(not_safe, (int(hover[-1]), 0))
    half = heights_ft[hover[-1]] / 2.0
    reaching = [column for column in range(len(speeds_kt)) if np.any(low_speed[heights_ft >= half, column])]
    knee_column = max(reaching)
    knee_height = heights_ft[np.flatnonzero(low_speed[:, knee_column])].max()
    row["knee"] = f"{speeds_kt[knee_column]:.0f} kt at {knee_height:.0f} ft"
    top_speed = np.flatnonzero(not_safe[:, -1])
    row["top speed"] = row[f"not safe at {speeds_kt[-1]:.0f} kt"] = (
        f"{heights_ft[top_speed[0]]:.0f}-{heights_ft[top_speed[-1]]:.0f} ft" if top_speed.size else "none"
    )
    fast = np.zeros_like(not_safe)
    fast[:, knee_column + 1 :] = True
    separate = not_safe & fast & ~low_speed
    if separate.any():
        rows, columns = np.nonzero(separate)
        row["separate high-speed region"] = (
            f"yes: {separate.sum()} nodes, {heights_ft[rows.min()]:.0f}-{heights_ft[rows.max()]:.0f} ft, "
            f"{speeds_kt[columns.min()]:.0f}-{speeds_kt[columns.max()]:.0f} kt"
        )
    elif top_speed.size:
        row["separate high-speed region"] = "no: the low-level band at speed joins the low-speed region"
    else:
        row["separate high-speed region"] = "no"
    return row


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("files", nargs="+", help="envelope .npz files")
    arguments = parser.parse_args()
    print(f"command: {command_line()}")
    print(f"load average (1/5/15 min): {loadavg_text()}")
    rows = [shape_row(path) for path in arguments.files]
    top = next((key for key in rows[0] if key.startswith("not safe at")), "top speed")
    columns = ["setting", "safe", "unsafe share", "hover band", "knee", top, "separate high-speed region", "file"]
    print("| " + " | ".join(columns) + " |")
    print("|" + "---|" * len(columns))
    for row in rows:
        print("| " + " | ".join(row[column] for column in columns) + " |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
