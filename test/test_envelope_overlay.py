"""Overlay plots of several envelopes and the compute flags that choose their settings ("Figures").

Two tiny envelopes (2 × 2 nodes, 300-400 ft, 40-50 kt; real IPOPT) computed by the command line with
``--method paper`` and ``--method verified --reaction-delay-s 0``; the labels' rules use hand-made envelopes.
"""

from __future__ import annotations

import pytest
from test_envelope import run_cli, synthetic_envelope
from test_envelope_3d import SAFE, stacked

from helireach_ros.core.envelope.data import Envelope, load_envelope
from helireach_ros.core.envelope.plot import overlay_figure, overlay_labels, region_outline
from helireach_ros.core.units import FT, LBF

PNG = b"\x89PNG\r\n\x1a\n"


def compute(out, *flags: str) -> None:
    result = run_cli("envelope", "compute", "--heights-ft", "300:400:2", "--speeds-kt", "40:50:2", "--workers", "1",
                     "--quiet", "--out", str(out), *flags)  # fmt: skip
    assert result.returncode == 0, result.stderr


@pytest.fixture(scope="module")
def paper_and_verified(tmp_path_factory):
    folder = tmp_path_factory.mktemp("overlay")
    compute(folder / "paper.npz", "--method", "paper")
    compute(folder / "verified.npz", "--method", "verified", "--reaction-delay-s", "0")
    return folder / "paper.npz", folder / "verified.npz"


def legend_texts(figure) -> list[str]:
    return [text.get_text() for legend in figure.legends for text in legend.get_texts()]


def test_method_and_delay_flags_are_recorded_in_the_files(paper_and_verified):
    paper, verified = (load_envelope(path) for path in paper_and_verified)
    assert paper.metadata["method"] == paper.metadata["settings"]["method"] == "paper"
    assert verified.metadata["method"] == "verified" and verified.metadata["settings"]["reaction_delay_s"] == 0.0
    assert "--method paper" in paper.metadata["command"]
    refused = run_cli("envelope", "compute", "--method", "magic", "--out", "unused.npz")
    assert refused.returncode == 2 and "invalid choice" in refused.stderr
    negative = run_cli("envelope", "compute", "--reaction-delay-s", "-1", "--out", "unused.npz")
    assert negative.returncode == 2 and "reaction_delay_s" in negative.stderr


def test_overlay_writes_one_figure_with_one_legend_entry_per_file(paper_and_verified, tmp_path):
    envelopes = [load_envelope(path) for path in paper_and_verified]
    texts = legend_texts(overlay_figure(envelopes))
    # the paper method flies the paper's rotor, the verified one the airframe's: the labels say so
    assert texts == ["paper, delay 0 s, paper rotor", "verified, delay 0 s, momentum rotor, ground effect"]
    out = tmp_path / "overlay.png"
    result = run_cli("envelope", "plot", *map(str, paper_and_verified), "--out", str(out))
    assert result.returncode == 0, result.stderr
    assert out.read_bytes()[:8] == PNG
    single = tmp_path / "single.png"  # one file: today's diagram
    assert run_cli("envelope", "plot", str(paper_and_verified[1]), "--out", str(single)).returncode == 0
    assert single.read_bytes()[:8] == PNG


def relabelled(envelope: Envelope, **changes) -> Envelope:
    metadata = envelope.metadata
    for key, value in changes.items():
        if key in ("gross_weight", "density_altitude"):
            metadata["airframe"][key] = value
        elif key == "reaction_delay_s":
            metadata.setdefault("settings", {})[key] = value
        else:
            metadata[key] = value
    return Envelope(envelope.arrays, metadata)


def test_labels_name_what_differs_and_the_climb_slice():
    base = relabelled(synthetic_envelope(SAFE), method="verified", gross_weight=16000 * LBF, density_altitude=0.0)
    delayed = relabelled(base, method="flyable", reaction_delay_s=1.0)
    assert overlay_labels([base, delayed]) == ["verified, delay 0 s", "flyable, delay 1 s"]
    heavy = relabelled(base, gross_weight=18000 * LBF, density_altitude=4000 * FT)
    assert overlay_labels([base, heavy]) == [
        "verified, delay 0 s, W 16,000 lbf, DA 0 ft",
        "verified, delay 0 s, W 18,000 lbf, DA 4,000 ft",
    ]
    # equal metadata: the file names tell them apart
    assert overlay_labels([base, base], ["a.npz", "b.npz"]) == [
        "verified, delay 0 s (a.npz)",
        "verified, delay 0 s (b.npz)",
    ]
    three_d = stacked([-1000, 0], [SAFE, SAFE], method="verified", airframe=base.metadata["airframe"])
    figure = overlay_figure([base, three_d], climb_rate=-900 * FT / 60.0)
    assert legend_texts(figure) == ["verified, delay 0 s", "verified, delay 0 s, -1,000 ft/min"]
    with pytest.raises(ValueError):
        overlay_figure([])


def test_the_overlay_outline_is_the_whole_edge_of_the_region_inside_the_grid():
    """One unsafe node in the middle: its region is the diamond through the four edge midpoints (no refined points)."""
    envelope = synthetic_envelope([["safe"] * 3, ["safe", "unsafe", "safe"], ["safe"] * 3])
    outline = {tuple(sorted(map(tuple, segment.tolist()))) for segment in region_outline(envelope)}
    diamond = [(5.0, 100.0), (10.0, 50.0), (15.0, 100.0), (10.0, 150.0)]
    assert outline == {tuple(sorted((diamond[k], diamond[(k + 1) % 4]))) for k in range(4)}
    border = synthetic_envelope([["unsafe", "safe", "safe"], ["safe"] * 3, ["safe"] * 3])  # a corner node
    assert {tuple(sorted(map(tuple, s.tolist()))) for s in region_outline(border)} == {((0.0, 50.0), (5.0, 0.0))}
