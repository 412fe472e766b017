"""planner.program.background: a function run beside the caller returns its value or raises."""

import numpy as np
import pytest

from planner.program.background import in_background


def _square(a):
    return a @ a


def _fail():
    raise ValueError("boom")


def test_the_value_comes_back_and_a_failure_is_raised_with_its_cause():
    a = np.arange(9.0).reshape(3, 3)
    assert np.array_equal(in_background(_square, a)(), a @ a)
    with pytest.raises(RuntimeError, match="ValueError: boom"):
        in_background(_fail)()


def test_a_forked_highs_solve_after_the_parent_used_highs():
    """HiGHS' thread scheduler, started in the parent, is dropped in the child before it
    solves (its workers are not inherited)."""
    import scipy.sparse as sp

    from planner.program.highs import WarmLP, reset_after_fork, run_highs

    def lp():
        return run_highs(np.ones(2), sp.csr_array(np.array([[2.0, 2.0]])), np.ones(1),
                         np.full(1, np.inf), np.zeros(2), np.ones(2), np.ones(2, np.int32),
                         10.0, 0.0).objective

    assert lp() == 1.0  # the parent's scheduler exists now
    assert in_background(lp, after_fork=reset_after_fork)() == 1.0
    warm = WarmLP(np.ones(2), sp.csr_array(np.array([[2.0, 2.0]])), np.ones(1),
                  np.full(1, np.inf), np.zeros(2), np.ones(2))
    assert in_background(lambda: warm.solve(10.0).objective, after_fork=reset_after_fork)() \
        == pytest.approx(0.5)
