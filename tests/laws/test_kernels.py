"""solver/laws/kernels.py: the sum of exponentials of a kernel meets its tolerance, checked independently on the
run's lags and on a dense log grid of [k, T]; short Prony series given as tables are found back; refusals say why."""

import math

import numpy as np
import pytest

from solver.laws.kernels import (
    MAX_CHECKED_LAGS,
    MAX_TERMS,
    ExponentialSum,
    KernelFitError,
    PowerKernel,
    TabulatedKernel,
    fit_exponential_sum,
    run_lags,
)

pytestmark = pytest.mark.serial  # no MPI in this layer: on 2 ranks each would run the same checks again


def rel(exact, approx):
    return np.max(np.abs(approx - exact) / np.abs(exact))


@pytest.mark.parametrize("alpha", [0.2, 0.5, 0.8])
@pytest.mark.parametrize("k,steps", [(1e-3, 1000), (1e-4, 10_000)])
@pytest.mark.parametrize("tol", [1e-6, 1e-8])
def test_power_kernel_sum_meets_the_tolerance_on_a_dense_grid(alpha, k, steps, tol):
    law = PowerKernel(1.5, alpha)
    fit = law.prony(k, steps, tol)
    assert 1 <= fit.terms <= MAX_TERMS and fit.error <= tol
    lags = k * np.arange(1, steps + 1)
    at_lags = rel(law.exact(lags), fit.prony(lags))
    dense = np.geomspace(k, k * steps, 50_000)  # between the lags too, on another grid than the fit's check
    between = rel(1.5 * dense ** -alpha, fit.prony(dense))
    assert at_lags <= fit.error * (1 + 1e-6) and between <= tol  # 1e-6: the sums round differently here
    assert max(at_lags, between) == pytest.approx(fit.error, rel=0.05)  # the error it reports is the one reached


def test_a_table_of_a_prony_kernel_gives_back_its_two_terms():
    """4,001 rows of 2 e^{-s/0.2} + 0.5 e^{-s/5} on [0, 1], read at lags on rows (k = 1/2000): two terms, the
    time constants and weights found to ~1e-10."""
    s = np.linspace(0.0, 1.0, 4001)
    table = TabulatedKernel(tuple(zip(s.tolist(), (2 * np.exp(-s / 0.2) + 0.5 * np.exp(-s / 5)).tolist())))
    for zero in (False, True):
        fit = table.prony(1 / 2000, 2000, 1e-8, zero=zero)
        assert fit.terms == 2 and fit.error <= 1e-12
        assert fit.prony.times == pytest.approx((0.2, 5.0), rel=1e-9)
        assert fit.prony.weights == pytest.approx((2.0, 0.5), rel=1e-9)
        assert fit.lag_min == (0.0 if zero else 1 / 2000)


def test_a_constant_part_is_a_constant_term():
    """1 + 2 e^{-s/0.1} tabulated at the lags: the exponential and a constant term (tau = inf, or a tau so long that
    it is constant over the run to the tolerance) of weight 1."""
    s = 0.01 * np.arange(201)
    table = TabulatedKernel(tuple(zip(s.tolist(), (1 + 2 * np.exp(-s / 0.1)).tolist())))
    fit = table.prony(0.01, 200, 1e-8)
    assert rel(table.exact(s[1:]), fit.prony(s[1:])) <= 1e-8
    assert fit.terms == 2 and fit.prony.times[0] == pytest.approx(0.1) and fit.prony.times[1] > 2.0 / 1e-8
    assert fit.prony.weights == pytest.approx((2.0, 1.0))


def test_a_negative_kernel_keeps_its_sign():
    table = TabulatedKernel(tuple((float(a), float(-np.exp(-a))) for a in np.linspace(0, 1, 11)))
    fit = table.prony(0.1, 8, 1e-8)
    assert fit.terms == 1 and fit.prony.weights[0] == pytest.approx(-1.0) and fit.prony.times[0] == pytest.approx(1.0)


def test_refusals_say_why():
    with pytest.raises(KernelFitError, match="g\\(0\\) is infinite"):
        PowerKernel(1.0, 0.5).prony(0.01, 100, 1e-8, zero=True)
    with pytest.raises(KernelFitError, match="one sign"):
        TabulatedKernel(((0.0, 1.0), (1.0, -1.0))).prony(0.01, 100, 1e-8)
    rows = np.linspace(0, 1, 101)  # lags between the rows of a fast exponential: the kinks cost ~1e-4
    coarse = TabulatedKernel(tuple(zip(rows.tolist(), (2 * np.exp(-rows / 0.2)).tolist())))
    with pytest.raises(KernelFitError) as err:
        coarse.prony(1e-3, 1000, 1e-8)
    reached = float(err.value.reason.split("best reached ")[1].split(";")[0])
    assert 1e-6 < reached < 1e-2 and "\n" not in err.value.reason
    with pytest.raises(ValueError, match="exponent"):
        PowerKernel(1.0, 1.0)
    with pytest.raises(ValueError, match="coefficient"):
        PowerKernel(0.0, 0.5)


def test_a_fit_that_needs_more_terms_than_the_budget_is_refused():
    """s^-alpha to 1e-13 over seven decades is past what double precision least squares reach within the budget."""
    with pytest.raises(KernelFitError, match=f"at most {MAX_TERMS}"):
        fit_exponential_sum(lambda s: s ** -0.5, np.geomspace(1e-7, 1.0, 5000), 1e-13)


def test_exponential_sum_and_lags():
    g = ExponentialSum((2.0, 0.5), (0.1, math.inf))
    assert g(np.array([0.0, 0.1])) == pytest.approx([2.5, 2 * math.exp(-1) + 0.5])
    assert run_lags(0.5, 4).tolist() == [0.5, 1.0, 1.5, 2.0]
    assert run_lags(0.5, 2, zero=True).tolist() == [0.0, 0.5, 1.0]
    long = run_lags(1e-7, 10_000_000)
    assert len(long) <= MAX_CHECKED_LAGS and long[0] == 1e-7 and long[-1] == pytest.approx(1.0)
