"""The interval code against published reference values."""

import pytest

from rlgrasp.stats import wilson_interval


@pytest.mark.parametrize(
    "k, n, low, high",
    [  # Wilson 95% intervals (e.g. statsmodels proportion_confint(method="wilson"))
        (8, 10, 0.4902, 0.9433),
        (0, 10, 0.0, 0.2775),
        (10, 10, 0.7225, 1.0),
        (95, 100, 0.8883, 0.9785),
    ],
)
def test_wilson_matches_reference(k, n, low, high):
    lo, hi = wilson_interval(k, n)
    assert lo == pytest.approx(low, abs=1e-4) and hi == pytest.approx(high, abs=1e-4)


def test_wilson_rejects_impossible_counts():
    with pytest.raises(ValueError, match="trials"):
        wilson_interval(0, 0)
    with pytest.raises(ValueError, match="successes"):
        wilson_interval(11, 10)


def test_wilson_matches_closed_form_formula():
    """Against the textbook formula written out independently, over many counts."""
    import math

    z = 1.959964
    for n in (1, 7, 50, 333):
        for k in range(0, n + 1, max(1, n // 9)):
            p = k / n
            c = (2 * k + z * z) / (2 * (n + z * z))
            h = z * math.sqrt(z * z + 4 * k * (1 - p)) / (2 * (n + z * z))
            lo, hi = wilson_interval(k, n)
            assert lo == pytest.approx(max(0.0, c - h), abs=1e-12)
            assert hi == pytest.approx(min(1.0, c + h), abs=1e-12)


def test_iqm_matches_scipy_trim_mean_values():
    from rlgrasp.stats import iqm, trimmed_mean

    # scipy.stats.trim_mean([1..8], 0.25) = mean(3, 4, 5, 6) = 4.5; with 10 values cut 2 per end.
    assert iqm([8, 1, 7, 2, 6, 3, 5, 4]) == pytest.approx(4.5)
    assert trimmed_mean(list(range(10)) + [1000], 0.25) == pytest.approx(5.0)  # outlier ignored
    assert iqm([[1.0, 2.0], [3.0, 100.0]]) == pytest.approx(2.5)


def test_stratified_bootstrap_ci_brackets_and_reproduces():
    import numpy as np

    from rlgrasp.stats import iqm, stratified_bootstrap_ci

    scores = [0.80, 0.90, 0.85, 0.95, 0.70]
    point, lo, hi = stratified_bootstrap_ci(scores, np.mean, reps=2000, seed=1)
    assert point == pytest.approx(np.mean(scores))
    assert lo <= point <= hi and 0.70 <= lo and hi <= 0.95
    assert stratified_bootstrap_ci(scores, np.mean, reps=2000, seed=1) == (point, lo, hi)
    # Percentile interval of the mean of 5 values: about mean +- 1.96 * sd / sqrt(5).
    half = 1.96 * np.std(scores) / np.sqrt(len(scores))
    assert (hi - lo) / 2 == pytest.approx(half, rel=0.25)
    # Identical runs: no uncertainty. Two tasks: each column is resampled within itself.
    assert stratified_bootstrap_ci([0.5, 0.5, 0.5], iqm) == (0.5, 0.5, 0.5)
    two = np.array([[0.0, 1.0], [0.0, 1.0], [0.0, 1.0]])
    assert stratified_bootstrap_ci(two, np.mean, reps=200) == (0.5, 0.5, 0.5)


def test_wilson_bounds_are_exact_at_the_extremes():
    assert wilson_interval(10, 10)[1] == 1.0
    assert wilson_interval(0, 10)[0] == 0.0
