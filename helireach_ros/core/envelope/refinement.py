"""Boundary-following refinement: which nodes of a grid coarser passes decide, and how.

With L levels, a grid of (2^L k + 1) nodes per axis is computed coarse to fine. The full grid procedure first runs
on the lattice of every 2^L-th node (:func:`lattice`); then, level by level, the lattice of half that step is
filled in. Each new node lies in one cell of the coarser lattice (a cell centre) or on the edge of one or two (an
edge midpoint), and gets what its enclosing cells' corners say (:func:`classify`):

- **every corner of every enclosing cell safe** — ``interior``: first the mean of its own corners' stored control
  functions (:func:`corners`: the 2 ends of its edge, or the 4 corners of its cell; the first control set to the
  node's own trim, which the NLP's plans start from) is replayed from the node's own state; if it lands within
  limits the node is ``safe`` on that plan without a solve (``interpolated``). Otherwise the node is solved once,
  warm-started from the mean of its corners' solver states, and the answer counts only if the NLP calls it safe
  *and* the stored plan lands within limits in the independent replay. Either way an interior node is ``safe`` on
  its own replay-verified plan, never on its corners' word; a node neither keeps is solved by the full grid
  procedure. The corners' mean plan lands at 19 % of the finest level's interior nodes of the 81 × 49 level slice
  (its corners 10 ft or 2.5 kt away) and at 0–3 % of the coarser levels' (the plans ride the rotor-speed limits,
  and the replay judges them as strictly as any plan). A cell with an ``unverified`` corner (the NLP found a
  landing that the replay did not confirm) is not interior: where the replay misses, the nodes beside it miss too
  (half of such interior solves did not verify on the OH-58A and S300C classes' diagrams, and each then cost the
  full procedure as well);
- **every corner unsafe** — ``inferred unsafe``: no solve; the node is stored ``unsafe`` with the smallest of its
  corners' values (the conservative direction: it may only hide a safe pocket, never claim one);
- **anything else** (corners that disagree, or failed or no-trim corners) — solved by the full grid
  procedure on that level's lattice (sweep and cold re-checks), as if no coarser pass had run.

The boundary refinement along grid lines then runs once, on the finest grid.

The H-V boundary runs through cells whose corners disagree, so the solves follow the boundary: their number grows
with the boundary's length rather than the grid's area, and the safe interior costs one warm solve per node
(measured in ``bench/envelope_resolution.py``). The refinement's codes per node are stored in the envelope file
(:data:`REFINEMENT_ARRAY`).
"""

from __future__ import annotations

import enum

import numpy as np

__all__ = ["REFINEMENT_ARRAY", "NodeOrigin", "check_refinable", "classify", "corners", "lattice"]

REFINEMENT_ARRAY = "refinement_origin"
"""Per-node int8 array of a refined envelope (:class:`NodeOrigin` values); absent in a full-grid file."""


class NodeOrigin(enum.IntEnum):
    """How a refined envelope's node got its answer."""

    GRID = 0
    """The full grid procedure (sweep, cold re-check, boundary), as in an unrefined envelope."""
    INTERIOR = 1
    """One warm solve inside cells whose corners are all safe, kept because its plan is safe and replay-verified."""
    INFERRED_UNSAFE = 2
    """No solve: inside cells whose corners are all unsafe, stored unsafe with the smallest corner value."""
    INTERPOLATED = 3
    """No solve: inside cells whose corners are all safe, on the mean of its corners' plans, which lands within
    limits when replayed from the node's own state (stored with that replay's value)."""


def check_refinable(counts: tuple[int, ...], levels: int) -> None:
    """Raises ValueError unless ``levels`` ≥ 0 and every axis count is 2^levels · k + 1 with k ≥ 1 (every
    level's grid is every other node of the next finer one)."""
    if levels < 0:
        raise ValueError(f"refinement levels must be >= 0, got {levels}")
    step = 2**levels
    for count in counts:
        if count < step + 1 or (count - 1) % step:
            raise ValueError(
                f"{levels} refinement level(s) need 2^{levels} k + 1 nodes per axis (e.g. {4 * step + 1}; every "
                f"level's grid is every other node of the next finer one), got {count}"
            )


def lattice(shape: tuple[int, int], step: int) -> np.ndarray:
    """Boolean mask of the nodes on every ``step``-th row and column."""
    mask = np.zeros(shape, bool)
    mask[::step, ::step] = True
    return mask


def corners(row: int, column: int, step: int = 1) -> list[tuple[int, int]]:
    """The nodes of the 2·``step`` lattice a node of the ``step`` lattice takes its warm start and inferred value
    from: the ends of its edge (one index an odd multiple of ``step``) or the corners of its cell (both)."""
    rows = [row] if row % (2 * step) == 0 else [row - step, row + step]
    columns = [column] if column % (2 * step) == 0 else [column - step, column + step]
    return [(r, c) for r in rows for c in columns]


def _enclosing_cells_agree(codes: np.ndarray, accepted: tuple[int, ...]) -> np.ndarray:
    """Per node of ``codes`` (a lattice of step 1 here, odd counts: every node lies in a cell): every cell of the
    every-other-node lattice containing it (1, 2 or 4 of them) has all four corners' codes in ``accepted``."""
    coarse = np.isin(codes[::2, ::2], accepted)
    cell_uniform = coarse[:-1, :-1] & coarse[1:, :-1] & coarse[:-1, 1:] & coarse[1:, 1:]
    agree = np.ones(codes.shape, bool)
    for cell_row, cell_column in np.ndindex(cell_uniform.shape):
        block = (slice(2 * cell_row, 2 * cell_row + 3), slice(2 * cell_column, 2 * cell_column + 3))
        agree[block] &= cell_uniform[cell_row, cell_column]
    return agree


def classify(
    codes: np.ndarray, step: int, safe_codes: tuple[int, ...], unsafe_code: int
) -> tuple[np.ndarray, np.ndarray]:
    """(interior, inferred_unsafe) masks over the whole grid for the nodes of the ``step`` lattice that are not on
    the 2·``step`` lattice, from the status codes of the 2·``step`` lattice's nodes in ``codes``: interior where
    every enclosing cell's corners are in ``safe_codes`` (the envelope passes ``safe``), inferred unsafe where all are
    ``unsafe_code``.

    A node of the level in neither mask is solved by the full grid procedure.
    """
    shape = codes.shape
    level = (slice(None, None, step), slice(None, None, step))
    interior, inferred_unsafe = np.zeros(shape, bool), np.zeros(shape, bool)
    new = lattice(shape, step) & ~lattice(shape, 2 * step)
    interior[level] = _enclosing_cells_agree(codes[level], safe_codes)
    inferred_unsafe[level] = _enclosing_cells_agree(codes[level], (unsafe_code,))
    return interior & new, inferred_unsafe & new
