"""H-V diagrams with the paper's rotor and the momentum rotor, without and with a 1 s reaction delay, per airframe.

Run: .venv/bin/python bench/hv_rotor_models.py [--out out/hv_rotor_models] [--figures docs/hv]
     [--airframes uh60a_class oh58a_class s300c_class] [--heights-ft 0:800:17] [--speeds-kt 0:120:13]

Computes one envelope per (airframe, rotor model, delay) with ``helireach envelope compute`` (flyable plans, the
default settings; files kept in --out, each with its command in its metadata), draws each airframe's four boundaries
in one figure (``<figures>/<airframe>_rotor_models.png``) and prints ``bench/hv_table.py``'s shape table for them
(hover band, knee, the low band at speed, a separate high-speed region).
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import time
from pathlib import Path

from baseline_config import loadavg_text
from hv_table import shape_row

ROTOR_MODELS = ("paper", "momentum")
DELAYS_S = (0.0, 1.0)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="out/hv_rotor_models")
    parser.add_argument("--figures", default="docs/hv")
    parser.add_argument("--airframes", nargs="+", default=["uh60a_class", "oh58a_class", "s300c_class"])
    parser.add_argument("--heights-ft", default="0:800:17")
    parser.add_argument("--speeds-kt", default="0:120:13")
    arguments = parser.parse_args(argv)
    out, figures = Path(arguments.out), Path(arguments.figures)
    out.mkdir(parents=True, exist_ok=True)
    figures.mkdir(parents=True, exist_ok=True)
    print(f"command: {' '.join(sys.argv)}\nload average (1/5/15 min): {loadavg_text()}", flush=True)
    helireach = [sys.executable, "-m", "helireach_ros.cli.main"]
    rows = []
    for airframe in arguments.airframes:
        files = []
        for rotor in ROTOR_MODELS:
            for delay in DELAYS_S:
                path = out / f"{airframe}_{rotor}_delay{delay:g}.npz"
                started = time.perf_counter()
                subprocess.run(
                    [*helireach, "envelope", "compute", "--airframe", airframe, "--rotor-model", rotor,
                     "--reaction-delay-s", f"{delay:g}", "--heights-ft", arguments.heights_ft,
                     "--speeds-kt", arguments.speeds_kt, "--out", str(path), "--quiet"],
                    check=True,
                )  # fmt: skip
                print(f"{path}: {time.perf_counter() - started:.0f} s, load {loadavg_text()}", flush=True)
                files.append(path)
                rows.append(shape_row(str(path)))
        figure = figures / f"{airframe}_rotor_models.png"
        subprocess.run(
            [*helireach, "envelope", "plot", *map(str, files), "--out", str(figure), "--title", airframe], check=True
        )
        print(f"figure: {figure}", flush=True)
    top = next((key for key in rows[0] if key.startswith("not safe at")), "top speed")
    columns = ["setting", "safe", "unsafe share", "hover band", "knee", top, "separate high-speed region"]
    print("| " + " | ".join(columns) + " |")
    print("|" + "---|" * len(columns))
    for row in rows:
        print("| " + " | ".join(row[column] for column in columns) + " |")
    print(f"load average (1/5/15 min): {loadavg_text()}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
