"""Derivatives of the closed-form fit: the weighted solve's own rule, the PCA's eigh rule, and
fit_polynomial under jvp / grad / jacfwd / jacrev / vmap / jit, against central finite differences."""

from __future__ import annotations

import collections

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from jax.test_util import check_grads

import polyjax as pj
from polyjax.internal import TALL_ROWS

from _problems import curet
from _robust_problems import random_hemisphere

FACTORISATIONS = ("qr", "svd", "eigh", "cholesky", "triangular_solve", "householder_product")


def _central(f, x, t, h=1e-6):
    """Central finite difference of ``f`` at ``x`` along ``t``."""
    return (f(x + h * t) - f(x - h * t)) / (2 * h)


def _count_factorisations(closed_jaxpr) -> dict[str, int]:
    """Dense factorisation primitives in a jaxpr and every jaxpr nested in it."""
    found = collections.Counter()

    def walk(jaxpr):
        for eqn in jaxpr.eqns:
            if eqn.primitive.name in FACTORISATIONS:
                found[eqn.primitive.name] += 1
            for p in eqn.params.values():
                for sub in p if isinstance(p, (list, tuple)) else (p,):
                    if hasattr(sub, "eqns"):
                        walk(sub)
                    elif hasattr(getattr(sub, "jaxpr", None), "eqns"):
                        walk(sub.jaxpr)

    walk(closed_jaxpr.jaxpr)
    return dict(found)


def _finite(tree) -> bool:  # on the host: a device reduction would compile two programs per new shape
    return all(bool(np.all(np.isfinite(np.asarray(a)))) for a in jax.tree.leaves(tree))


# ---------------------------------------------------------------------------------------------------------------
# weighted_lstsq


def _lstsq_problem(case, seed=0):
    """(design, y, weights, active, tangents); tangents vanish at zero-weight samples (w = 0 is a kink:
    negative weights are clipped) and keep the rank of a rank-deficient design."""
    rng = np.random.default_rng(seed)
    n, m, r = (7, 6, 2) if case == "fewer-rows" else (40, 6, 2)
    d = rng.normal(size=(n, m)) * np.array([1.0, 10.0, 0.1, 1.0, 3.0, 1.0])  # unequal column scales
    y = rng.normal(size=(n, r))
    w = rng.uniform(0.1, 2.0, n)
    w[:3] = 0.0
    td, ty, tw = rng.normal(size=d.shape), rng.normal(size=y.shape), rng.normal(size=w.shape)
    tw[:3] = 0.0
    active = np.ones(m, bool)
    if case == "inactive":
        active[-1] = False
    return d, y, w, active, (td, ty, tw)


@pytest.mark.parametrize("method", ["qr", "svd"])
@pytest.mark.parametrize("case", ["full", "inactive", "fewer-rows"])
def test_lstsq_jvp_matches_finite_differences(method, case):
    """The rule's derivative w.r.t. design, y and weights equals central differences to ~1e-8 relative,
    also for a rank-deficient design (4 weighted rows, 6 columns: the Golub-Pereyra terms of the
    minimum-norm solution, including the equilibration's derivative, are needed to pass)."""
    d, y, w, active, (td, ty, tw) = _lstsq_problem(case)
    sol = pj.weighted_lstsq(jnp.asarray(d), jnp.asarray(y), jnp.asarray(w), jnp.asarray(active), method=method)
    assert int(sol.rank) == (4 if case == "fewer-rows" else int(active.sum()))

    def coef(d, y, w):
        return pj.weighted_lstsq(d, y, w, jnp.asarray(active), method=method).coefficients

    args = [jnp.asarray(a) for a in (d, y, w)]
    for i, t in enumerate((td, ty, tw)):
        def along(x, i=i):
            a = list(args)
            a[i] = x
            return coef(*a)

        _, jv = jax.jvp(along, (args[i],), (jnp.asarray(t),))
        ref = _central(along, args[i], jnp.asarray(t))
        scale = float(jnp.max(jnp.abs(ref)))
        assert scale > 1e-3
        np.testing.assert_allclose(np.asarray(jv), np.asarray(ref), rtol=0, atol=1e-7 * max(scale, 1.0))
    if not active.all():
        assert np.all(np.asarray(jax.jacfwd(lambda y: coef(args[0], y, args[2]))(args[1]))[-1] == 0.0)
    # reverse mode: the same rule transposed
    check_grads(coef, (args[0], args[1], args[2] + 0.1), order=1, modes=("rev",), eps=1e-6)


def test_lstsq_tall_cholesky_qr2_path_differentiates():
    """The CholeskyQR2 path (n >= TALL_ROWS) has the same rule: jvp against central differences, grad finite."""
    rng = np.random.default_rng(4)
    n = TALL_ROWS + 100
    d = jnp.asarray(rng.normal(size=(n, 5)))
    y = jnp.asarray(rng.normal(size=n))
    w = jnp.asarray(rng.uniform(0.1, 1.0, n))
    tw = jnp.asarray(rng.normal(size=n))

    def coef(w):
        return pj.weighted_lstsq(d, y, w).coefficients

    _, jv = jax.jvp(coef, (w,), (tw,))
    np.testing.assert_allclose(np.asarray(jv), np.asarray(_central(coef, w, tw)), rtol=0, atol=1e-9)
    assert _finite(jax.grad(lambda w: jnp.sum(coef(w) ** 2))(w))


def test_lstsq_zero_weight_samples_contribute_exactly_zero():
    """Samples with weight 0 (even with NaN/inf values and design rows, and nonzero tangents everywhere)
    give the derivative of the fit without them, exactly finite; before, sqrt(max(w, 0)) gave NaN."""
    d, y, w, _, (td, ty, tw) = _lstsq_problem("full", seed=1)
    d[0, 2], y[1, 0], td[2, 1] = np.inf, np.nan, np.nan  # rows 0..2 have weight 0
    tw[:3] = 1.0

    def coef(d, y, w):
        return pj.weighted_lstsq(d, y, w).coefficients

    full = jax.jvp(coef, tuple(jnp.asarray(a) for a in (d, y, w)), tuple(jnp.asarray(a) for a in (td, ty, tw)))
    kept = jax.jvp(coef, tuple(jnp.asarray(a[3:]) for a in (d, y, w)), tuple(jnp.asarray(a[3:]) for a in (td, ty, tw)))
    assert _finite(full)
    np.testing.assert_allclose(np.asarray(full[1]), np.asarray(kept[1]), rtol=1e-12, atol=1e-14)
    grads = jax.grad(lambda d, y, w: jnp.sum(coef(d, y, w)), argnums=(0, 1, 2))(*(jnp.asarray(a) for a in (d, y, w)))
    assert _finite(grads)
    assert all(np.all(np.asarray(g)[:3] == 0.0) for g in grads)


def test_lstsq_singular_values_and_condition_tangents():
    """``singular_values`` and ``condition`` differentiate (ds_k = u_k^T dA v_k of the equilibrated design);
    ``rank`` has a float0 tangent."""
    d, y, w, _, (td, _, tw) = _lstsq_problem("full", seed=2)
    d, y, w, td, tw = (jnp.asarray(a) for a in (d, y, w, td, tw))

    def spectrum(d, w):
        sol = pj.weighted_lstsq(d, y, w)
        return jnp.concatenate([sol.singular_values, sol.condition[None]])

    _, jv = jax.jvp(spectrum, (d, w), (td, tw))
    ref = _central(lambda e: spectrum(d + e * td, w + e * tw), 0.0, 1.0)
    np.testing.assert_allclose(np.asarray(jv), np.asarray(ref), rtol=1e-6, atol=1e-8)
    _, t_rank = jax.jvp(lambda d: pj.weighted_lstsq(d, y, w).rank, (d,), (td,))
    assert t_rank.dtype == jax.dtypes.float0
    # rank-deficient (condition inf): every float output differentiates finite in reverse mode
    d, y, w = (jnp.asarray(a) for a in _lstsq_problem("fewer-rows")[:3])
    sol = pj.weighted_lstsq(d, y, w)
    assert np.isinf(float(sol.condition))

    def floats(d, y, w):
        sol = pj.weighted_lstsq(d, y, w)
        return sol.coefficients, sol.condition, sol.singular_values

    assert _finite(jax.jacrev(floats, argnums=(0, 1, 2))(d, y, w))


def test_lstsq_derivative_reuses_the_factorisation():
    """No LAPACK differentiation: the jaxprs of jvp, grad, jacfwd and jacrev hold the primal's one QR and one
    SVD, nothing more (no second QR, no triangular solves of differentiated factors)."""
    d, y, w, _, _ = _lstsq_problem("full", seed=3)
    d, y, w = (jnp.asarray(a) for a in (d, y, w))

    def f(d, y, w):
        return jnp.sum(pj.weighted_lstsq(d, y, w).coefficients ** 2)

    primal = _count_factorisations(jax.make_jaxpr(f)(d, y, w))
    assert primal == {"qr": 1, "svd": 1}
    args = (d, y, w)
    assert _count_factorisations(jax.make_jaxpr(lambda *a: jax.jvp(f, a, a))(*args)) == primal
    for transform in (jax.grad, jax.jacfwd, jax.jacrev):
        assert _count_factorisations(jax.make_jaxpr(transform(f, argnums=(0, 1, 2)))(*args)) == primal


# ---------------------------------------------------------------------------------------------------------------
# eigh / PCA


def _symmetric_directions(n, seed=0):
    """(u, v) closed under mirroring u in x, in y, and swapping x <-> y in both: the anisotropic Lafortune
    variables (ux vx, uy vy, uz vz) then have covariance diag(a, a, b), a tied eigenvalue."""
    u, v = random_hemisphere(n, seed=seed, min_cos=0.3)
    us, vs = [], []
    for fx, fy in ((1, 1), (1, -1), (-1, 1), (-1, -1)):
        for swap in ([0, 1, 2], [1, 0, 2]):
            us.append((u * [fx, fy, 1])[:, swap])
            vs.append(v[:, swap])
    return np.concatenate(us), np.concatenate(vs)


def _samples_of_covariance(c, n=40, seed=0):
    """``(z, b)``: samples ``x = z b`` (``n x 3``) whose covariance (``fit_pca``'s, ``n - 1`` in the denominator) is
    ``c = b^T b`` exactly: ``z`` centred and white."""
    rng = np.random.default_rng(seed)
    r = rng.normal(size=(n, 3))
    q, _ = np.linalg.qr(r - r.mean(axis=0))
    w, v = np.linalg.eigh(c)
    return q * np.sqrt(n - 1.0), np.diag(np.sqrt(w)) @ v.T


def test_eigh_rule_matches_finite_differences_and_holds_ties_fixed():
    """The PCA's eigh rule, through ``fit_pca`` of samples whose covariance moves along a symmetric ``t``.
    Distinct eigenvalues: variances and (sign-fixed) directions against central differences. A tied pair:
    finite; the tied eigenspace's projector and the sum of its variances are exact."""
    rng = np.random.default_rng(0)
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    t = rng.normal(size=(3, 3))
    t = t + t.T

    def along(c):
        """``x(e)`` with covariance ``c + e t`` to first order: ``x = z (b + e db)``, ``b^T db + db^T b = t``."""
        z, b = _samples_of_covariance(c)
        db = 0.5 * np.linalg.solve(b.T, t)
        return jnp.asarray(z @ b), jnp.asarray(z @ db)

    def pca(x):
        p = pj.fit_pca(x)
        return p.variance, p.rotation  # decreasing variances; the PCA's sign rule fixes each direction's sign

    x, dx = along(q @ np.diag([0.5, 1.0, 2.0]) @ q.T)
    _, (dw, dv) = jax.jvp(pca, (x,), (dx,))
    ref = _central(lambda e: jnp.concatenate([a.ravel() for a in pca(x + e * dx)]), 0.0, 1.0)
    np.testing.assert_allclose(np.asarray(jnp.concatenate([dw, dv.ravel()])), np.asarray(ref), atol=1e-8)
    np.testing.assert_allclose(np.asarray(dw), np.diag(np.asarray(pca(x)[1]).T @ t @ np.asarray(pca(x)[1])),
                               atol=1e-10)  # d lambda_i = r_i^T dC r_i

    tied, dtied = along(q @ np.diag([0.5, 2.0, 2.0]) @ q.T)

    def space(x):
        w, v = pca(x)
        return jnp.concatenate([(v[:, :2] @ v[:, :2].T).ravel(), (w[0] + w[1])[None], w[2:]])

    _, jv = jax.jvp(space, (tied,), (dtied,))
    _, (dw, dv) = jax.jvp(pca, (tied,), (dtied,))
    assert _finite((dw, dv))
    np.testing.assert_allclose(np.asarray(jv), np.asarray(_central(space, tied, dtied)), atol=1e-8)
    assert _finite(jax.jacrev(lambda x: pca(x)[1])(tied))


def test_fit_at_tied_pca_eigenvalues():
    """Hard case: samples symmetric under mirroring and x <-> y, anisotropic Lafortune variables, covariance
    diag(a, a, b). Degree 1 does not depend on the undetermined rotation in the tied eigenspace, and its L2
    and values pass check_grads w.r.t. u, v and values; degree 3 does depend on it (not differentiable
    there): its derivatives are finite."""
    u, v = (jnp.asarray(a) for a in _symmetric_directions(12))
    y = jnp.asarray(np.random.default_rng(1).uniform(0.1, 1.0, u.shape[0]))
    pca = pj.fit_pca(pj.explanatory_variables("lafortune-anisotropic", u, v))
    assert abs(float(pca.variance[0] - pca.variance[1])) < 1e-12 * float(pca.variance[0])

    def fit(u, v, y, degree):
        m = pj.fit_polynomial(u, v, y, variables="lafortune-anisotropic", degree=degree)
        return m.l2, m(u[:5], v[3:8])

    check_grads(jax.jit(lambda u, v, y: fit(u, v, y, 1)), (u, v, y), order=1, modes=("fwd", "rev"), eps=1e-6)
    assert _finite(jax.jit(jax.jacrev(lambda u, v, y: fit(u, v, y, 3), argnums=(0, 1, 2)))(u, v, y))


# ---------------------------------------------------------------------------------------------------------------
# fit_polynomial on CUReT (default settings: method="qr", 80-degree cutoff, Legendre basis)


@pytest.fixture(scope="module")
def quarry():
    data = curet((25,))
    u, v, values, weights = (jnp.asarray(a) for a in (data.u, data.v, data.values[0], data.weights))
    keep = np.asarray(pj.cutoff_mask(u, v))
    assert 0 < (~keep).sum() < keep.size  # the default cutoff drops samples: their derivatives are tested
    return u, v, values, weights, keep


def _fit_outputs(values, weights, u, v):
    model = pj.fit_polynomial(u, v, values, weights=weights)
    return model.coefficients, model.l2, model(u[:9], v[4:13])


@pytest.mark.data
@pytest.mark.parametrize("wrt", ["values", "weights", "u", "v"])
def test_check_grads_fit_polynomial_curet(quarry, wrt):
    """check_grads (forward and reverse, order 1) of the coefficients, the L2 and the model at new directions,
    on Quarry tile with the default cutoff (16 samples cut), under jit."""
    u, v, values, weights, _ = quarry
    args = {"values": values, "weights": weights, "u": u, "v": v}

    def f(x):
        return _fit_outputs(**{**args, wrt: x})

    check_grads(jax.jit(f), (args[wrt],), order=1, modes=("fwd", "rev"), eps=1e-6)


@pytest.mark.data
def test_fit_jacobians_vmap_and_jit_agree(quarry):
    """jacfwd == jacrev of the L2 w.r.t. all four inputs; vmap of grad over 4 materials equals the
    grads one at a time; every derivative finite, and exactly zero at the samples the cutoff drops."""
    u, v, values, weights, keep = quarry

    def l2(values, weights, u, v):
        return pj.fit_polynomial(u, v, values, weights=weights).l2

    argnums = (0, 1, 2, 3)
    jf = jax.jit(jax.jacfwd(l2, argnums=argnums))(values, weights, u, v)
    jr = jax.jit(jax.jacrev(l2, argnums=argnums))(values, weights, u, v)
    assert _finite(jf)
    for a, b in zip(jf, jr):
        np.testing.assert_allclose(np.asarray(a), np.asarray(b), rtol=1e-9, atol=1e-15)
    for a in jf:
        assert np.all(np.asarray(a)[~keep] == 0.0)

    many = jnp.asarray(curet((1, 25, 33, 55)).values)
    grad = jax.grad(l2, argnums=(0, 1, 2))
    batched = jax.jit(jax.vmap(grad, in_axes=(0, None, None, None)))(many, weights, u, v)
    single = jax.jit(grad)
    for i in range(4):
        one = single(many[i], weights, u, v)
        for a, b in zip(batched, one):
            np.testing.assert_allclose(np.asarray(a[i]), np.asarray(b), rtol=1e-9, atol=1e-15)


@pytest.mark.data
def test_jvp_with_cut_samples_not_nan(quarry):
    """The reported bug: jvp of the L2 w.r.t. the weights or u with the default 80-degree cutoff was NaN.
    Now finite and equal to central differences; also with a mask and a NaN value dropped by
    nonfinite="mask", and a zero weight given by the user."""
    u, v, values, weights, _ = quarry
    rng = np.random.default_rng(5)
    tw, tu = jnp.asarray(rng.normal(size=weights.shape)), jnp.asarray(rng.normal(size=u.shape))
    mask = np.ones(values.shape, bool)
    mask[10:20] = False
    vals = np.array(values)
    vals[30] = np.nan
    w0 = np.array(weights)
    w0[40] = 0.0

    def l2(weights, u):
        return pj.fit_polynomial(u, v, jnp.asarray(vals), weights=weights, mask=jnp.asarray(mask), nonfinite="mask").l2

    along_w = (jnp.asarray(w0), tw.at[40].set(0.0), lambda x: l2(x, u))  # w = 0 is a kink: no tangent there
    along_u = (u, tu, lambda x: l2(jnp.asarray(w0), x))
    for x, t, g in (along_w, along_u):
        _, jv = jax.jvp(g, (x,), (t,))
        assert np.isfinite(float(jv))
        np.testing.assert_allclose(float(jv), float(_central(g, x, t)), rtol=1e-6)
    gw, gu = jax.grad(lambda w, u: l2(w, u)[()], argnums=(0, 1))(jnp.asarray(w0), u)
    assert _finite((gw, gu))
    assert np.all(np.asarray(gw)[10:20] == 0.0) and float(gw[30]) == 0.0


@pytest.mark.data
def test_fit_derivative_reuses_the_factorisations(quarry):
    """The derivatives of the whole fit hold the primal's factorisations only: one eigh (PCA), one QR, one
    SVD; jvp, grad, jacfwd and jacrev add none (LAPACK's differentiation would add QR/triangular solves)."""
    u, v, values, weights, _ = quarry

    def l2(u):
        return pj.fit_polynomial(u, v, values, weights=weights).l2[()]

    primal = _count_factorisations(jax.make_jaxpr(l2)(u))
    assert primal == {"eigh": 1, "qr": 1, "svd": 1}
    assert _count_factorisations(jax.make_jaxpr(lambda x: jax.jvp(l2, (x,), (x,)))(u)) == primal
    for transform in (jax.grad, jax.jacfwd, jax.jacrev):
        assert _count_factorisations(jax.make_jaxpr(transform(l2))(u)) == primal


def test_rank_deficient_fit_has_finite_minimum_norm_derivatives():
    """6 samples, degree 5 (11 parameters): RANK_DEFICIENT, minimum-norm. The derivatives w.r.t. values
    and weights (which keep the rank) equal central differences; w.r.t. u they are finite."""
    u, v = (jnp.asarray(a) for a in random_hemisphere(6, seed=3, min_cos=0.3))
    y = 0.2 + u[:, 2] * v[:, 2] + 0.1 * u[:, 0] * v[:, 0]
    w = jnp.asarray(np.random.default_rng(2).uniform(0.5, 2.0, 6))
    model = pj.fit_polynomial(u, v, y, weights=w, degree=5)
    assert int(model.status) == pj.RESULTS.RANK_DEFICIENT and int(model.rank) == 6

    def coef(y, w):
        m = pj.fit_polynomial(u, v, y, weights=w, degree=5)
        return jnp.concatenate([m.coefficients, m(u[:3] + 0.1 * v[:3], v[:3])])

    rng = np.random.default_rng(3)
    for i, x in enumerate((y, w)):
        t = jnp.asarray(rng.normal(size=x.shape))
        g = (lambda x: coef(x, w)) if i == 0 else (lambda x: coef(y, x))
        _, jv = jax.jvp(g, (x,), (t,))
        ref = _central(g, x, t)
        np.testing.assert_allclose(np.asarray(jv), np.asarray(ref), rtol=0, atol=1e-7 * float(jnp.max(jnp.abs(ref))))
    assert _finite(jax.jacrev(lambda u: pj.fit_polynomial(u, v, y, weights=w, degree=5).coefficients)(u))


def test_empty_lane_and_perfect_fit_do_not_poison_the_batch():
    """A lane with every sample masked (L2 inf) and a lane fitted exactly (L2 0) beside a normal lane: the
    Jacobian of the L2s is finite (sqrt at 0 gave NaN, which reached the shared u), 0 for those two lanes,
    and the normal lane's row equals its fit alone. The same for l2_error."""
    u, v = (jnp.asarray(a) for a in random_hemisphere(40, seed=3, min_cos=0.2))
    b = 0.2 + v[:, 2] + 0.3 * u[:, 0] * v[:, 0]
    values = jnp.stack([b, b, jnp.zeros_like(b)])
    mask = jnp.asarray(np.arange(3)[:, None] != 1) & jnp.ones((3, 40), bool)

    def l2(u, values):
        return pj.fit_polynomial(u, v, values, degree=3, mask=mask).l2

    l2s = l2(u, values)
    assert np.isinf(float(l2s[1])) and float(l2s[2]) == 0.0 and float(l2s[0]) > 0
    ju, jv = jax.jacrev(l2, argnums=(0, 1))(u, values)
    assert _finite((ju, jv))
    assert np.all(np.asarray(ju[1:]) == 0.0) and np.all(np.asarray(jv[1:]) == 0.0)
    alone_u, alone_v = jax.jacrev(lambda u, b: pj.fit_polynomial(u, v, b, degree=3).l2, argnums=(0, 1))(u, b)
    np.testing.assert_allclose(np.asarray(ju[0]), np.asarray(alone_u), rtol=1e-9, atol=1e-14)
    np.testing.assert_allclose(np.asarray(jv[0, 0]), np.asarray(alone_v), rtol=1e-9, atol=1e-14)
    jm = jax.jacrev(lambda x: pj.l2_error(x, 0.1 + 0.0 * x, u, v, mask=mask))(values.at[2].set(0.1))
    assert _finite(jm) and np.all(np.asarray(jm[1:]) == 0.0)
