"""Importance sampling of BRDFs: chi-square of sample against pdf, normalisation, the map, gradients."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import polyjax.render as pr
from polyjax.render import cosine_sample, hemisphere_to_square, square_to_hemisphere

from _sampling_problems import (
    GRAZING,
    NORMAL,
    OBLIQUE,
    TABLE,
    chi2_pvalue,
    cook_torrance,
    glossy_polynomial,
    neural,
    sample_many,
    ward,
)

N_SAMPLES = 200_000


def _check_chi2(brdf, view, **kw):
    """Chi-square of samples for ``view`` against the density; views with an azimuth are rotated back to
    azimuth 0 (samples and view alike), which also checks that the density turns with the view."""
    s = pr.importance_sampler(brdf, resolution=TABLE, **kw)
    u, p = sample_many(s, view, N_SAMPLES)
    assert np.all(np.isfinite(u)) and np.all(p > 0)
    np.testing.assert_allclose(np.linalg.norm(u, axis=1), 1.0, atol=1e-12)
    np.testing.assert_allclose(p, np.asarray(s.pdf(jnp.asarray(u), jnp.asarray(view))), rtol=1e-12)
    phi = np.arctan2(view[1], view[0])
    c, si = np.cos(phi), np.sin(phi)
    back = np.array([[c, si, 0.0], [-si, c, 0.0], [0.0, 0.0, 1.0]])
    u, view = u @ back.T, back @ view
    np.testing.assert_allclose(p, np.asarray(s.pdf(jnp.asarray(u), jnp.asarray(view))), rtol=1e-9)
    pval = chi2_pvalue(u, lambda w: s.pdf(w, jnp.asarray(view)))
    assert pval > 1e-3, pval
    return s


def test_map_is_area_preserving_and_inverted():
    xi = jax.random.uniform(jax.random.PRNGKey(0), (4096, 2), jnp.float64)
    w = square_to_hemisphere(xi)
    np.testing.assert_allclose(np.linalg.norm(w, axis=-1), 1.0, atol=1e-14)
    np.testing.assert_allclose(hemisphere_to_square(w), xi, atol=1e-12)
    # equal solid angle: uniform squares give uniform cos theta (mean 1/2, variance 1/12)
    z = np.asarray(w[:, 2])
    assert abs(z.mean() - 0.5) < 0.02 and abs(z.var() - 1 / 12) < 0.005
    zc = np.asarray(cosine_sample(xi)[:, 2])  # cosine-weighted: cos^2 theta uniform
    assert abs((zc**2).mean() - 0.5) < 0.02


@pytest.mark.parametrize("view", [NORMAL, GRAZING], ids=["normal", "grazing"])
@pytest.mark.parametrize("make", [cook_torrance, ward], ids=["cook-torrance", "ward"])
def test_chi2_baselines(make, view):
    _check_chi2(make(), view)


def test_chi2_oblique_azimuth_phong():
    _check_chi2(pr.Phong(0.05, 0.9, 80.0), OBLIQUE)


@pytest.mark.data
@pytest.mark.parametrize("view", [NORMAL, GRAZING], ids=["normal", "grazing"])
def test_chi2_glossy_merl_polynomial(view):
    model = glossy_polynomial()
    assert float(np.min(model(jnp.asarray(GRAZING), jnp.asarray([[0.0, 0.99, 0.141]])))) is not None
    _check_chi2(model, view)


@pytest.mark.data
@pytest.mark.parametrize("view", [NORMAL, GRAZING], ids=["normal", "grazing"])
def test_chi2_neural(view):
    _check_chi2(neural(), view)


def test_chi2_detects_a_wrong_density():
    """The test can fail: samples of one sampler against the density of another."""
    a = pr.importance_sampler(pr.Phong(0.05, 0.9, 80.0), resolution=TABLE)
    b = pr.importance_sampler(pr.Phong(0.05, 0.9, 60.0), resolution=TABLE)
    u, _ = sample_many(a, GRAZING, N_SAMPLES)
    assert chi2_pvalue(u, lambda w: b.pdf(w, jnp.asarray(GRAZING))) < 1e-6


@pytest.mark.parametrize("view", [NORMAL, OBLIQUE, GRAZING, np.array([0.999, 0.0, 0.0447])],
                         ids=["normal", "oblique", "grazing", "beyond-last-node"])
def test_pdf_integrates_to_one(view):
    s = pr.importance_sampler(cook_torrance())
    n = 64 * 16  # quadrature aligned with the 64 x 64 table: exact for the tabulated part at view azimuth 0
    g = (np.arange(n) + 0.5) / n
    w = square_to_hemisphere(jnp.stack(jnp.meshgrid(g, g), -1))
    v = jnp.asarray(view / np.linalg.norm(view))
    total = float(jnp.sum(s.pdf(w, v))) * 2 * np.pi / n**2
    assert abs(total - 1.0) < (1e-3 if view[1] != 0 else 1e-6), total
    below = jnp.asarray([[0.3, 0.1, -0.5], [1.0, 0.0, 0.0]])
    np.testing.assert_array_equal(np.asarray(s.pdf(below, v)), 0.0)


def test_density_positive_where_brdf_positive_even_for_negative_models():
    """A BRDF negative over most of the hemisphere: the table is 0 there but the cosine term keeps pdf > 0."""

    def negative_lobe(u, v):
        return 3.0 * jnp.sum(u * v * jnp.array([-1.0, -1.0, 1.0]), -1) - 2.0

    s = pr.importance_sampler(negative_lobe, alpha=0.2)
    xi = jax.random.uniform(jax.random.PRNGKey(3), (5000, 2), jnp.float64)
    u = square_to_hemisphere(xi * 0.999 + 0.0005)
    p = np.asarray(s.pdf(u, jnp.asarray(OBLIQUE)))
    np.testing.assert_array_less(0.2 * np.asarray(u[:, 2]) / np.pi * (1 - 1e-12), p)
    _check_chi2(negative_lobe, OBLIQUE, alpha=0.2)


def test_all_zero_brdf_falls_back_to_uniform_table():
    s = pr.importance_sampler(lambda u, v: jnp.zeros(u.shape[:-1]))
    np.testing.assert_allclose(np.asarray(s.density), 1.0)


def test_vmap_over_views_and_gradient_wrt_view():
    s = pr.importance_sampler(cook_torrance())
    views = jnp.asarray(np.stack([NORMAL, OBLIQUE, GRAZING]))
    keys = jax.random.split(jax.random.PRNGKey(0), 3)
    u, p = jax.vmap(s.sample, in_axes=(0, 0, None))(keys, views, 16)
    assert u.shape == (3, 16, 3) and p.shape == (3, 16)
    np.testing.assert_allclose(p, jax.vmap(s.pdf)(u, views), rtol=1e-12)
    xi = jax.random.uniform(jax.random.PRNGKey(1), (64, 5), jnp.float64)

    def first_coordinate(v):
        return jnp.sum(s.warp(xi, v / jnp.linalg.norm(v))[0][:, 0])

    g = jax.grad(first_coordinate)(jnp.asarray(OBLIQUE))
    assert np.all(np.isfinite(np.asarray(g))) and np.any(np.asarray(g) != 0)


def test_bad_arguments_raise():
    from polyjax import InputError

    with pytest.raises(InputError, match="alpha"):
        pr.importance_sampler(pr.Phong(), alpha=0.0)
    with pytest.raises(InputError, match="theta_max_deg"):
        pr.importance_sampler(pr.Phong(), theta_max_deg=90.0)
    with pytest.raises(InputError, match="resolution"):
        pr.importance_sampler(pr.Phong(), resolution=0)


def test_density_is_continuous_across_cell_edges():
    """Points just either side of every cell edge of the table (in the square of the map): the density differs by
    no more than its slope allows (a piecewise-constant table would jump by up to the whole lobe there)."""
    s = pr.importance_sampler(cook_torrance(), resolution=TABLE)
    edges = np.arange(1, TABLE) / TABLE
    other = (np.arange(TABLE) + 0.37) / TABLE
    E, O = np.meshgrid(edges, other)
    for axis in (0, 1):
        pts = np.stack([E, O] if axis == 0 else [O, E], -1).reshape(-1, 2)
        step = np.zeros(2)
        step[axis] = 1e-9
        below = s.pdf(square_to_hemisphere(jnp.asarray(pts - step)), jnp.asarray(GRAZING))
        above = s.pdf(square_to_hemisphere(jnp.asarray(pts + step)), jnp.asarray(GRAZING))
        scale = float(jnp.max(below))
        assert float(jnp.max(jnp.abs(above - below))) < 1e-5 * scale
        assert scale > 10 * 0.1 / np.pi  # a lobe well above the cosine floor


def test_tables_integrate_the_bilinear_density():
    """The sampler's tables (its public ``density``, ``prefix`` and ``row_cdf``) are exact for the bilinear
    interpolant of the density's nodes: the density integrates to 1, ``prefix`` holds its integrals along the rows
    and ``row_cdf`` the CDF of its ``y``-marginal (what the exact inversion of ``warp`` relies on)."""
    n = 6
    s = pr.importance_sampler(cook_torrance(), resolution=n, n_views=3)
    m = 600  # midpoint rule on sub-cells: exact for a bilinear function on each cell
    c = (np.arange(m) + 0.5) / m
    f = (c * n) - np.clip(np.floor(c * n), 0, n - 1)
    i = np.clip(np.floor(c * n), 0, n - 1).astype(int)
    for j in range(s.n_views):
        Q = np.asarray(s.density[j])
        assert np.ptp(Q) > 0.1 * Q.max()  # a lobe, not a flat table
        rows_x = (1 - f)[None, :] * Q[:, i] + f[None, :] * Q[:, i + 1]  # q at row nodes, x on the midpoints
        np.testing.assert_allclose(np.asarray(s.prefix[j, :, -1]), rows_x.mean(axis=1), rtol=1e-12)
        at = m // 2  # x = 1/2, a node of the 6-cell grid: the prefix there is the integral over [0, 1/2]
        np.testing.assert_allclose(np.asarray(s.prefix[j, :, n // 2]), rows_x[:, :at].mean(axis=1) / 2, rtol=1e-12)
        full = (1 - f)[:, None] * rows_x[i] + f[:, None] * rows_x[i + 1]
        np.testing.assert_allclose(full.mean(), 1.0, rtol=1e-12)
        np.testing.assert_allclose(float(s.row_cdf[j, -1]), 1.0, rtol=1e-12)
        np.testing.assert_allclose(np.asarray(s.row_cdf[j, 3]), full[: m // 2].mean() / 2, rtol=1e-12)
