"""Smooth stand-ins for non-smooth functions, so the NLP has finite derivatives everywhere (CasADi or floats)."""

from __future__ import annotations

import casadi as ca

__all__ = ["smooth_positive"]


def smooth_positive(value, width: float):
    """A smooth, strictly positive stand-in for max(value, 0).

    .. math:: s(x) = \\tfrac12\\big(x + \\sqrt{x^2 + w^2}\\big)

    Equal to ``value`` to within ``w²/(4x)`` for ``x ≫ w``, and ``w/2`` at 0.
    """
    return 0.5 * (value + ca.sqrt(value**2 + width**2))
