"""Legendre–Gauss–Radau points, Lagrange differentiation and quadrature (numpy only).

Two uses:

* the paper's single-interval scheme uses the N LGR points on [−1, 1), which include −1
  (Garg et al. 2010; Shen, Tang & Wang 2011, §3.3), with the non-collocated support point +1;
* the verified scheme uses Radau IIA points on (0, 1] inside each of many intervals (the
  flipped LGR points, which include the interval's end).

For N LGR points, quadrature with the LGR weights is exact for polynomials of degree ≤ 2N − 2, and
the differentiation matrix of the degree-N interpolant through N + 1 support points is exact for
polynomials of degree ≤ N.
"""

from __future__ import annotations

import numpy as np
from numpy.polynomial import legendre

__all__ = [
    "barycentric_weights",
    "lagrange_basis_derivatives",
    "lagrange_basis_values",
    "lgr_points",
    "lgr_weights",
    "radau_iia_points",
]


def lgr_points(count: int) -> np.ndarray:
    """The ``count`` Legendre–Gauss–Radau points on [−1, 1), ascending, the first being −1.

    They are the roots of :math:`P_{N-1}(\\tau) + P_N(\\tau)`.
    """
    if count < 1:
        raise ValueError(f"need at least one LGR point, got {count}")
    if count == 1:
        return np.array([-1.0])
    coefficients = np.zeros(count + 1)
    coefficients[count - 1] = 1.0
    coefficients[count] = 1.0
    roots = np.sort(np.real(legendre.legroots(coefficients)))
    roots[0] = -1.0
    # One Newton step per root on the Legendre form tightens the companion-matrix roots to ~1e-15.
    derivative = legendre.legder(coefficients)
    interior = roots[1:]
    roots[1:] = interior - legendre.legval(interior, coefficients) / legendre.legval(interior, derivative)
    return roots


def lgr_weights(points: np.ndarray) -> np.ndarray:
    """The LGR quadrature weights for :func:`lgr_points` of the same count.

    .. math:: w_1 = 2/N^2, \\qquad w_i = \\frac{1 - \\tau_i}{N^2 P_{N-1}(\\tau_i)^2}
    """
    count = len(points)
    previous = np.zeros(count)
    previous[count - 1] = 1.0
    weights = (1.0 - points) / (count**2 * legendre.legval(points, previous) ** 2)
    weights[0] = 2.0 / count**2
    return weights


def radau_iia_points(degree: int) -> np.ndarray:
    """The ``degree`` Radau IIA points on (0, 1], ascending, the last being 1."""
    return np.sort((1.0 - lgr_points(degree)) / 2.0)


def barycentric_weights(support: np.ndarray) -> np.ndarray:
    """Barycentric weights :math:`1/\\prod_{k\\ne j}(t_j - t_k)` of a set of distinct support points."""
    differences = support[:, None] - support[None, :]
    np.fill_diagonal(differences, 1.0)
    return 1.0 / np.prod(differences, axis=1)


def lagrange_basis_values(support: np.ndarray, at: np.ndarray) -> np.ndarray:
    """Matrix ``L[i, j] = L_j(at[i])`` of the Lagrange basis on ``support``.

    ``L @ values`` interpolates values given at the support points.
    """
    support = np.asarray(support, dtype=float)
    at = np.atleast_1d(np.asarray(at, dtype=float))
    weights = barycentric_weights(support)
    differences = at[:, None] - support[None, :]
    exact = np.isclose(differences, 0.0, rtol=0.0, atol=1e-14)
    differences[exact] = 1.0
    terms = weights[None, :] / differences
    basis = terms / terms.sum(axis=1, keepdims=True)
    rows = exact.any(axis=1)
    basis[rows] = exact[rows].astype(float)
    return basis


def lagrange_basis_derivatives(support: np.ndarray, at: np.ndarray) -> np.ndarray:
    """Matrix ``D[i, j] = L_j'(at[i])``: ``D @ values`` differentiates the interpolant.

    With ``at`` a subset of ``support`` this is the collocation differentiation matrix (the
    paper's D, of size N × (N + 1) for N collocation points and N + 1 support points).
    """
    support = np.asarray(support, dtype=float)
    at = np.atleast_1d(np.asarray(at, dtype=float))
    weights = barycentric_weights(support)
    count = len(support)
    derivatives = np.zeros((len(at), count))
    for row, point in enumerate(at):
        match = np.flatnonzero(np.isclose(support, point, rtol=0.0, atol=1e-14))
        if match.size:
            i = int(match[0])
            others = np.arange(count) != i
            derivatives[row, others] = weights[others] / weights[i] / (point - support[others])
            derivatives[row, i] = -derivatives[row, others].sum()
        else:
            # d/dt of the barycentric form, for points off the support.
            offsets = point - support
            values = weights / offsets
            total = values.sum()
            basis = values / total
            derivative_terms = -weights / offsets**2
            derivatives[row] = (derivative_terms - basis * derivative_terms.sum()) / total
    return derivatives
