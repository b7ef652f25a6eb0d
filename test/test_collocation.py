"""Collocation exactness: LGR differentiation to degree N, LGR quadrature to degree 2N − 2."""

import numpy as np
import pytest
from numpy.polynomial import polynomial

from helireach_ros.core.ocp.collocation import (
    lagrange_basis_derivatives,
    lagrange_basis_values,
    lgr_points,
    lgr_weights,
    radau_iia_points,
)


def _random_polynomial(degree: int, seed: int) -> np.ndarray:
    return np.random.default_rng(seed).normal(size=degree + 1)


@pytest.mark.parametrize("count", [2, 3, 5, 10, 24])
def test_lgr_points_include_minus_one_and_exclude_one(count):
    points = lgr_points(count)
    assert len(points) == count
    assert points[0] == -1.0
    assert np.all(np.diff(points) > 0)
    assert points[-1] < 1.0


@pytest.mark.parametrize("count", [2, 3, 5, 10, 24])
def test_differentiation_is_exact_to_degree_n(count):
    collocation = lgr_points(count)
    support = np.append(collocation, 1.0)  # N + 1 support points: the paper's N × (N + 1) matrix
    derivative_matrix = lagrange_basis_derivatives(support, collocation)
    assert derivative_matrix.shape == (count, count + 1)
    coefficients = _random_polynomial(count, seed=count)
    exact = polynomial.polyval(collocation, polynomial.polyder(coefficients))
    approximate = derivative_matrix @ polynomial.polyval(support, coefficients)
    np.testing.assert_allclose(approximate, exact, rtol=1e-9, atol=1e-9 * np.abs(coefficients).sum() * count**2)


@pytest.mark.parametrize("count", [2, 3, 5])
def test_differentiation_is_not_exact_beyond_degree_n(count):
    collocation = lgr_points(count)
    support = np.append(collocation, 1.0)
    monomial = np.zeros(count + 2)
    monomial[-1] = 1.0  # τ^(N+1)
    exact = polynomial.polyval(collocation, polynomial.polyder(monomial))
    approximate = lagrange_basis_derivatives(support, collocation) @ polynomial.polyval(support, monomial)
    assert np.max(np.abs(approximate - exact)) > 1e-3


@pytest.mark.parametrize("count", [2, 3, 5, 10, 24])
def test_quadrature_is_exact_to_degree_2n_minus_2(count):
    points = lgr_points(count)
    weights = lgr_weights(points)
    coefficients = _random_polynomial(2 * count - 2, seed=100 + count)
    integral = polynomial.polyint(coefficients)
    exact = polynomial.polyval(1.0, integral) - polynomial.polyval(-1.0, integral)
    assert weights @ polynomial.polyval(points, coefficients) == pytest.approx(exact, rel=1e-10, abs=1e-10)


@pytest.mark.parametrize("count", [2, 3, 4])
def test_quadrature_is_not_exact_at_degree_2n_minus_1(count):
    points = lgr_points(count)
    weights = lgr_weights(points)
    degree = 2 * count - 1
    exact = (1.0 - (-1.0) ** (degree + 1)) / (degree + 1)  # ∫ τ^degree over [−1, 1]
    assert abs(weights @ points**degree - exact) > 1e-3


def test_radau_iia_points_end_at_one_inside_unit_interval():
    points = radau_iia_points(3)
    np.testing.assert_allclose(points, [(4 - np.sqrt(6)) / 10, (4 + np.sqrt(6)) / 10, 1.0], atol=1e-14)


def test_lagrange_interpolation_reproduces_polynomials_between_nodes():
    support = np.array([0.0, 0.2, 0.7, 1.0])
    at = np.linspace(-0.1, 1.1, 13)
    coefficients = _random_polynomial(3, seed=7)
    np.testing.assert_allclose(
        lagrange_basis_values(support, at) @ polynomial.polyval(support, coefficients),
        polynomial.polyval(at, coefficients),
        atol=1e-12,
    )
    np.testing.assert_allclose(
        lagrange_basis_derivatives(support, at) @ polynomial.polyval(support, coefficients),
        polynomial.polyval(at, polynomial.polyder(coefficients)),
        atol=1e-10,
    )
