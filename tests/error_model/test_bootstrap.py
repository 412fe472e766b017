"""Bootstrap intervals against an analytic case (the mean of normal data)."""

from __future__ import annotations

import numpy as np

from error_model.bootstrap import bootstrap


def _coverage(n, max_rows, trials=200):
    rng = np.random.default_rng(0)
    hits, widths = 0, []
    for _ in range(trials):
        x = rng.normal(1.0, 2.0, n)
        res = bootstrap(lambda rows, x=x: np.array([x[rows].mean()]), np.arange(n), 100,
                        max_rows, rng)
        lo, hi = res.interval(np.array([x.mean()]))
        hits += lo[0] <= 1.0 <= hi[0]
        widths.append(hi[0] - lo[0])
    return hits / trials, float(np.mean(widths))


def test_percentile_interval_has_nominal_coverage_and_width():
    cov, width = _coverage(400, 400)
    assert 0.89 <= cov <= 0.99
    assert abs(width - 2 * 1.96 * 2.0 / np.sqrt(400)) < 0.05


def test_m_out_of_n_rescaling_gives_the_full_sample_width():
    cov, width = _coverage(1600, 400)
    assert 0.88 <= cov <= 0.99
    assert abs(width - 2 * 1.96 * 2.0 / np.sqrt(1600)) < 0.03


def test_same_seed_same_replicates():
    x = np.arange(50.0)
    a = bootstrap(lambda r: np.array([x[r].mean()]), np.arange(50), 10, 50,
                  np.random.default_rng(3))
    b = bootstrap(lambda r: np.array([x[r].mean()]), np.arange(50), 10, 50,
                  np.random.default_rng(3))
    np.testing.assert_array_equal(a.samples, b.samples)
    assert a.shrink == 1.0


def test_group_bootstrap_accounts_for_shared_scan_errors():
    """Rows of a group share an offset: the interval must reflect the between-group spread."""
    rng = np.random.default_rng(1)
    hits_group = hits_rows = 0
    trials = 150
    groups = np.repeat(np.arange(40), 20)
    for _ in range(trials):
        x = 1.0 + rng.normal(0, 1.0, 40)[groups] + rng.normal(0, 1.0, groups.size)
        est = np.array([x.mean()])
        for g, key in ((groups, "group"), (np.arange(groups.size), "rows")):
            res = bootstrap(lambda rows, x=x: np.array([x[rows].mean()]), g, 60, groups.size,
                            rng)
            lo, hi = res.interval(est)
            hit = lo[0] <= 1.0 <= hi[0]
            hits_group += hit and key == "group"
            hits_rows += hit and key == "rows"
    assert hits_group / trials > 0.88
    assert hits_rows / trials < 0.6  # ignoring the groups is badly over-confident
