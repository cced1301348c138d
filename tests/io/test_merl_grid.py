"""The MERL grid: coarse grids and their weights, sub-grids of a full table, lookup."""

from __future__ import annotations

import functools

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from brdffit import MeasurementsError, ParameterError
from brdffit.core.geometry import (
    MERL_SHAPE,
    halfdiff_to_io,
    merl_bin_centres,
    merl_solid_angle_weights,
    spherical_to_vector,
)
from brdffit.io.merl_grid import (
    MERL_N_CELLS,
    lookup,
    merl_grid,
    merl_grid_measurements,
    merl_subgrid,
)

N = MERL_N_CELLS


@functools.cache
def _id_table():
    """Full table whose R value is the cell's flat index + 1; 1% of cells unmeasured."""
    cube = np.broadcast_to(np.arange(1.0, N + 1.0).reshape(MERL_SHAPE), (3, *MERL_SHAPE)).copy()
    cube[:, np.random.default_rng(2).random(MERL_SHAPE) < 0.01] = -1.0
    return merl_grid_measurements(cube, source="cell ids")


# --------------------------------------------------------------------------- grids


@pytest.mark.parametrize("stride", [(1, 1, 1), (3, 3, 3), (5, 5, 5), (9, 9, 9), (3, 5, 9)])
def test_grid_weights_sum_to_two_pi_squared(stride):
    g = merl_grid(stride)
    assert g.n == int(np.prod(g.shape))
    total = g.weights[g.above].sum() / (2 * np.pi) ** 2
    # Weights are the summed fine-cell weights of each block, so over all cells the sum
    # is the full grid's whatever the stride; over the valid cells the horizon cuts
    # coarser cells: measured 1.5e-4 (full) to 8.7e-3 (stride 9), so 1.2e-2 at most.
    assert abs(total - 1) < (1e-3 if stride == (1, 1, 1) else 1.2e-2)
    np.testing.assert_allclose(g.weights.sum(), merl_grid().weights.sum(), rtol=1e-12)


def test_grid_directions_match_geometry():
    g = merl_grid((3, 3, 3))
    wi, wo = halfdiff_to_io(g.theta_h, g.theta_d, g.phi_d)
    # The grid's separable closed form performs the same operations: same bits.
    np.testing.assert_allclose(g.wi, wi, rtol=0, atol=1e-15)
    np.testing.assert_allclose(g.wo, wo, rtol=0, atol=1e-15)
    np.testing.assert_array_equal(g.above, (wi[:, 2] > 0) & (wo[:, 2] > 0))
    i = np.ravel_multi_index(np.indices(g.shape).reshape(3, -1) * 3 + 1, MERL_SHAPE)
    np.testing.assert_array_equal(g.index, i)
    np.testing.assert_allclose(g.theta_h, merl_bin_centres()[0].ravel()[i], rtol=1e-15)
    np.testing.assert_allclose(g.phi_d, merl_bin_centres()[2].ravel()[i], rtol=1e-15)


def test_grid_weights_match_coarse_cell_formula():
    g = merl_grid((3, 3, 3))
    coarse = merl_solid_angle_weights(g.theta_h, g.theta_d, shape=g.shape)
    ratio = (g.weights / coarse).reshape(g.shape)
    # Block sum vs the midpoint formula with coarse widths: they differ by the midpoint
    # error, ~(cell width / theta)^2 -- 89% in the first cell at theta = 0, where the
    # integrand sin(th) u dth grows like u^3, 0.7% from the sixth cell on.
    assert np.abs(ratio[5:, 5:] - 1).max() < 1e-2
    assert np.abs(ratio[0, 0, 0] - 1) < 1


@pytest.mark.parametrize("stride", [2, (1, 1, 4), (7, 1, 1), (1, 2)])
def test_bad_stride(stride):
    with pytest.raises(ParameterError, match="odd divisor|3 ints"):
        merl_grid(stride)


def test_subgrid_picks_bin_centres_of_the_full_table():
    table = _id_table()
    sub = merl_subgrid(table, (5, 5, 5))
    g = merl_grid((5, 5, 5))
    assert sub.n == 18 * 18 * 36 and sub.grid is None
    np.testing.assert_array_equal(sub.values, table.values[g.index])
    np.testing.assert_array_equal(sub.valid, table.valid[g.index])
    np.testing.assert_array_equal(sub.theta_d, table.theta_d[g.index])
    np.testing.assert_array_equal(sub.wi, table.wi[g.index])
    np.testing.assert_array_equal(sub.weights, g.weights)
    assert not sub.synthetic


def test_subgrid_of_synthetic_data_stays_synthetic():
    """A model's own values, picked on a sub-grid, are still that model's: the fit's
    default errors (``errors="auto"``) must not switch to the measured-data kind."""
    table = _id_table().replace(synthetic=True)
    assert merl_subgrid(table, (5, 5, 5)).synthetic
    assert merl_subgrid(table, 1).synthetic


def test_grid_measurements_marks_non_finite_invalid():
    g = merl_grid((9, 9, 9))
    cube = np.ones((3, *g.shape))
    cube[1, 5, 5, 5] = np.nan
    data = merl_grid_measurements(cube, source="x", stride=(9, 9, 9))
    flat = np.ravel_multi_index((5, 5, 5), g.shape)
    assert not data.channel_valid[flat, 1] and data.values[flat, 1] == -1.0
    assert data.channel_valid[flat, [0, 2]].all() == bool(g.above[flat])
    assert data.n_valid == g.above.sum()
    with pytest.raises(MeasurementsError, match="expected"):
        merl_grid_measurements(np.ones((3, 9, 9, 9)), source="x", stride=(9, 9, 9))


# --------------------------------------------------------------------------- lookup


def test_lookup_at_bin_centres_returns_the_stored_cell():
    g = merl_grid((3, 3, 3))  # 54,000 bin centres spread over the whole table
    stored = _id_table().values[g.index]
    got = lookup(_id_table(), g.wi, g.wo)
    measured, above = stored[:, 0] > 0, g.above
    np.testing.assert_array_equal(got[above & measured], stored[above & measured])
    assert np.isnan(got[above & ~measured]).all()
    assert (got[~above] == 0).all()
    raw = lookup(_id_table(), g.wi[~measured], g.wo[~measured], unmeasured="raw")
    np.testing.assert_array_equal(raw[above[~measured]], -1.0)


def _brute_force_cells(wi: np.ndarray, wo: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Nearest MERL bin centre per (n, 3) pair by exhaustive search over each axis.

    Angles come from the frame of the half vector (``d = (wi.ex, wi.ey, wi.h)``), not
    from :mod:`brdffit.core.geometry`. Returns the flat cell index and a mask that is False
    where the bin is ambiguous (left to round-off).
    """
    h = (wi + wo) / np.linalg.norm(wi + wo, axis=1, keepdims=True)
    theta_h = np.arctan2(np.hypot(h[:, 0], h[:, 1]), h[:, 2])
    phi_h = np.arctan2(h[:, 1], h[:, 0])
    ch, sh, cp, sp = np.cos(theta_h), np.sin(theta_h), np.cos(phi_h), np.sin(phi_h)
    ex = np.stack([ch * cp, ch * sp, -sh], axis=1)
    ey = np.stack([-sp, cp, np.zeros_like(cp)], axis=1)
    dx, dy, dz = (np.sum(wi * e, axis=1) for e in (ex, ey, h))
    theta_d = np.arctan2(np.hypot(dx, dy), dz)
    phi_d = np.mod(np.arctan2(dy, dx), np.pi)  # MERL folds phi_d by pi
    # phi_h or phi_d is undefined at theta_h = 0 or theta_d = 0: round-off picks the bin.
    ok = np.minimum(theta_h, theta_d) > 1e-6
    coords = (np.sqrt(theta_h / (np.pi / 2)), theta_d / (np.pi / 2), phi_d / np.pi)
    idx = []
    for axis, (x, n) in enumerate(zip(coords, MERL_SHAPE, strict=True)):
        t = x * n
        # Skip points at a bin edge. theta = 0 is no edge (bin 0 starts there);
        # phi_d = 0 = pi is one (the fold joins bins 179 and 0).
        edge = (np.abs(t - np.round(t)) < 1e-9) & ((axis == 2) | ((t > 0.5) & (t < n - 0.5)))
        ok &= ~edge
        centres = (np.arange(n) + 0.5) / n
        idx.append(np.argmin(np.abs(centres[None, :] - x[:, None]), axis=1))
    return np.ravel_multi_index(idx, MERL_SHAPE), ok


def _expected(flat: np.ndarray) -> np.ndarray:
    r = _id_table().values[flat, 0]
    return np.where(r > 0, r, np.nan)


def test_lookup_matches_brute_force_at_random_directions():
    rng = np.random.default_rng(4)
    n = 30_000
    wi = spherical_to_vector(rng.uniform(0, np.pi / 2, n), rng.uniform(0, 2 * np.pi, n))
    wo = spherical_to_vector(rng.uniform(0, np.pi / 2, n), rng.uniform(0, 2 * np.pi, n))
    flat, ok = _brute_force_cells(wi, wo)
    assert ok.mean() > 0.999
    got = lookup(_id_table(), wi, wo)[:, 0]
    np.testing.assert_array_equal(got[ok], _expected(flat[ok]))


@settings(max_examples=100, deadline=None)
@given(
    st.floats(0, np.pi / 2 - 1e-6),
    st.floats(0, 2 * np.pi),
    st.floats(0, np.pi / 2 - 1e-6),
    st.floats(0, 2 * np.pi),
)
def test_lookup_matches_brute_force_nearest_bin(t_i, p_i, t_o, p_o):
    wi = spherical_to_vector(np.array([t_i]), np.array([p_i]))
    wo = spherical_to_vector(np.array([t_o]), np.array([p_o]))
    assume(np.linalg.norm(wi + wo) > 1e-6)
    flat, ok = _brute_force_cells(wi, wo)
    assume(ok[0])
    np.testing.assert_array_equal(lookup(_id_table(), wi, wo)[:, 0], _expected(flat))


def test_lookup_below_horizon_is_zero():
    data = _id_table()
    wi = np.array([[0.0, 0.6, 0.8], [0.6, 0.0, -0.8], [1.0, 0.0, 0.0]])
    wo = np.array([[0.0, 0.0, -1.0], [0.0, 0.0, 1.0], [0.0, 0.0, 1.0]])
    np.testing.assert_array_equal(lookup(data, wi, wo), 0.0)


def test_lookup_needs_a_full_table_and_a_known_mode():
    table = _id_table()
    wi = np.array([[0.0, 0.0, 1.0]])
    with pytest.raises(MeasurementsError, match="full MERL table"):
        lookup(merl_subgrid(table, 3), wi, wi)
    with pytest.raises(ParameterError, match="accepted"):
        lookup(table, wi, wi, unmeasured="zero")
