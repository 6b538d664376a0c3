"""Tests of the sort-and-sweep broad phase against brute-force AABB overlap."""
from __future__ import annotations

import numpy as np
import pytest

from nscd.contact.broad import broad_phase


def brute_force(lower, upper, margin):
    """All pairs i < j whose boxes overlap on every axis once grown by margin, O(n^2)."""
    hit = ((lower[None, :, :] <= upper[:, None, :] + margin)
           & (lower[:, None, :] <= upper[None, :, :] + margin)).all(axis=2)
    i, j = np.nonzero(np.triu(hit, k=1))
    return np.stack((i, j), axis=1)


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("seed", range(4))
def test_random_boxes_match_brute_force(dim, seed):
    rng = np.random.default_rng(seed)
    n = 300
    lower = rng.uniform(0.0, 10.0, (n, dim))
    upper = lower + rng.uniform(0.0, 1.5, (n, dim))
    margin = rng.uniform(0.0, 0.3)
    expected = brute_force(lower, upper, margin)
    assert len(expected) > 50  # the case is not trivially empty
    np.testing.assert_array_equal(broad_phase(lower, upper, margin), expected)


@pytest.mark.parametrize("dim", [2, 3])
def test_elongated_clusters_match_brute_force(dim):
    # spread mostly along the last axis (the sweep axis then is not x), many equal keys
    rng = np.random.default_rng(11)
    n = 200
    lower = np.round(rng.uniform(0.0, 4.0, (n, dim)), 1)
    lower[:, -1] *= 10.0
    upper = lower + np.round(rng.uniform(0.0, 1.0, (n, dim)), 1)
    for margin in (0.0, 0.05):
        np.testing.assert_array_equal(broad_phase(lower, upper, margin),
                                      brute_force(lower, upper, margin))


def test_grid_of_touching_squares_known_count():
    # k x k unit squares sharing edges: 2 k (k - 1) edge neighbours and
    # 2 (k - 1)^2 corner neighbours (diagonal boxes touch at a point)
    k = 7
    x, y = np.meshgrid(np.arange(k, dtype=float), np.arange(k, dtype=float))
    lower = np.c_[x.ravel(), y.ravel()]
    pairs = broad_phase(lower, lower + 1.0, margin=0.0)
    assert len(pairs) == 2 * k * (k - 1) + 2 * (k - 1) ** 2
    # a gap of 0.1 between squares, margin below it: nothing; at it: all neighbours again
    assert len(broad_phase(1.1 * lower, 1.1 * lower + 1.0, margin=0.05)) == 0
    assert len(broad_phase(1.25 * lower, 1.25 * lower + 1.0, margin=0.25)) == 2 * k * (k - 1) + 2 * (k - 1) ** 2


def test_output_is_sorted_int_pairs_with_i_less_than_j():
    rng = np.random.default_rng(3)
    lower = rng.uniform(0.0, 3.0, (100, 3))
    pairs = broad_phase(lower, lower + 1.0, 0.0)
    assert pairs.dtype == np.int64 and pairs.shape[1] == 2
    assert (pairs[:, 0] < pairs[:, 1]).all()
    keys = pairs[:, 0] * 1000 + pairs[:, 1]
    assert (np.diff(keys) > 0).all()


def test_exclude_callable_and_mask():
    rng = np.random.default_rng(5)
    n = 80
    lower = rng.uniform(0.0, 5.0, (n, 2))
    upper = lower + 1.0
    fixed = np.zeros(n, dtype=bool)
    fixed[::3] = True
    full = brute_force(lower, upper, 0.0)
    expected = full[~(fixed[full[:, 0]] & fixed[full[:, 1]])]
    by_callable = broad_phase(lower, upper, 0.0, exclude=lambda i, j: fixed[i] & fixed[j])
    np.testing.assert_array_equal(by_callable, expected)
    mask = np.zeros((n, n), dtype=bool)
    mask[np.ix_(fixed, fixed)] = True
    mask = np.tril(mask)  # one triangle is enough: (i, j) or (j, i) excludes
    np.testing.assert_array_equal(broad_phase(lower, upper, 0.0, exclude=mask), expected)


@pytest.mark.parametrize("n", [0, 1])
def test_fewer_than_two_boxes(n):
    lower = np.zeros((n, 3))
    assert broad_phase(lower, lower + 1.0, 0.1).shape == (0, 2)


def test_bad_input_raises_naming_the_parameter():
    lower = np.zeros((4, 2))
    with pytest.raises(ValueError, match="margin == -0.1"):
        broad_phase(lower, lower + 1.0, -0.1)
    with pytest.raises(ValueError, match="upper.shape"):
        broad_phase(lower, np.ones((4, 3)), 0.0)
    upper = lower + 1.0
    upper[2, 1] = -1.0
    with pytest.raises(ValueError, match="box 2"):
        broad_phase(lower, upper, 0.0)
    with pytest.raises(ValueError, match=r"exclude.shape == \(3, 3\)"):
        broad_phase(lower, lower + 1.0, 0.0, exclude=np.zeros((3, 3), dtype=bool))
