"""Derivatives of the nonlinear fits (``baselines.fit``) by the implicit function theorem, against central finite
differences on real CUReT data (sample 25, default 80-degree cutoff).

The finite-difference reference fits each perturbed problem with ``baselines.fit`` and then takes Newton steps on
the full Hessian of the objective (written here, independently of the library), so that it sees the exact optimum
and not the solver's tolerance."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import baselines as bl
import polyjax as pj

KW = dict(n_starts=4, rtol=1e-12, atol=1e-14, max_steps=300)


@pytest.fixture(scope="module")
def curet():
    data = pj.data.load_curet(samples=[25])
    return tuple(jnp.asarray(a) for a in (data.values, data.weights, data.u, data.v))


def _objective(model, raw, y, w, u, v):
    """Equation (11) squared, written out: kept samples have theta_u, theta_v <= 80 degrees."""
    keep = (u[:, 2] >= np.cos(np.radians(80.0))) & (v[:, 2] >= np.cos(np.radians(80.0)))
    f = model.evaluate(model.to_params(raw), u, v)
    r = jnp.where(keep, u[:, 2] * (y - jnp.where(keep, f, 0.0)), 0.0)
    return jnp.sum(w * r * r) / jnp.sum(jnp.where(keep, w, 0.0))


def _exact_fit(name, y, w, u, v):
    """(params, l2) of one lane at the optimum polished by Newton steps (full Hessian)."""
    model = bl.get_model(name)
    raw = bl.fit(name, u, v, y, weights=w, **KW).raw[0]
    loss = lambda r: _objective(model, r, y[0], w, u, v)  # noqa: E731
    for _ in range(4):
        raw = raw - jnp.linalg.solve(jax.hessian(loss)(raw), jax.grad(loss)(raw))
    return model.to_params(raw), jnp.sqrt(loss(raw))


def _normalised(args, i):
    args = list(args)
    if i >= 2:
        args[i] = args[i] / jnp.linalg.norm(args[i], axis=-1, keepdims=True)
    return args


@pytest.mark.data
@pytest.mark.slow  # a forward and a reverse derivative of the fit compiled per model: about a minute on 2 cores
@pytest.mark.parametrize("name, which", [("ward", (0, 1, 2, 3)), ("cook-torrance", (0, 1))])
def test_jvp_and_grad_match_finite_differences(curet, name, which):
    # Cook-Torrance's shadowing term min(1, 2 (n.h)(n.u) / (v.h)) has a kink within 4e-7 of two CUReT samples
    # (153 and 190), so its derivative w.r.t. the directions is tested on Ward only
    rng = np.random.default_rng(0)

    def point(xs):
        """The fit's arguments with those in ``which`` replaced by ``xs`` (directions among them renormalised)."""
        args = list(curet)
        for i, x in zip(which, xs):
            args = _normalised(args[:i] + [x] + args[i + 1:], i)
        return args

    def fitted(xs):
        y, w, u, v = point(xs)
        f = bl.fit(name, u, v, y, weights=w, **KW)
        return f.params[0], f.l2[0]

    # one compiled forward derivative and one reverse gradient w.r.t. every argument in ``which`` (rather than a
    # program per argument): the derivative along argument i is the forward derivative along a tangent that is
    # zero in every other argument, and its reverse counterpart is the gradient's block i, so each argument's
    # derivative is checked on its own, as before, against its own finite difference
    xs = tuple(curet[i] for i in which)
    jvp = jax.jit(lambda xs_, ts_: jax.jvp(fitted, (xs_,), (ts_,)))
    g_all = jax.jit(jax.grad(lambda xs_: fitted(xs_)[1]))(xs)
    exact = jax.jit(lambda *a: _exact_fit(name, *a))
    for k, i in enumerate(which):
        x = curet[i]
        t = jnp.asarray(rng.normal(size=x.shape)) * (jnp.abs(x) if i < 2 else 0.1)
        ts = tuple(t if j == k else jnp.zeros_like(a) for j, a in enumerate(xs))
        (p0, l0), (dp, dl) = jvp(xs, ts)
        eps = 1e-5
        pp, lp = exact(*point(xs[:k] + (x + eps * t,) + xs[k + 1:]))
        pm, lm = exact(*point(xs[:k] + (x - eps * t,) + xs[k + 1:]))
        fd_p, fd_l = (pp - pm) / (2 * eps), (lp - lm) / (2 * eps)
        assert np.max(np.abs(dp - fd_p)) <= 1e-4 * np.max(np.abs(fd_p)), (name, i, dp, fd_p)
        assert abs(dl - fd_l) <= 1e-4 * abs(fd_l), (name, i, dl, fd_l)
        # reverse mode agrees with forward mode, and is finite although samples are cut
        g = g_all[k]
        assert bool(jnp.all(jnp.isfinite(g)))
        np.testing.assert_allclose(jnp.sum(g * t), dl, rtol=1e-9)


@pytest.mark.data
def test_grad_under_jit_and_vmap_with_masks(curet):
    y, w, u, v = curet
    # two lanes with different masks (one drops 20 samples): vmap of grad of the L2 w.r.t. values and weights
    masks = jnp.stack([jnp.ones(y.shape[-1], bool), jnp.arange(y.shape[-1]) % 10 != 3])

    def l2(yy, ww, m):
        return bl.fit("blinn-phong", u, v, yy, weights=ww, mask=m, n_starts=4).l2.sum()

    gy, gw = jax.jit(jax.vmap(jax.grad(l2, argnums=(0, 1)), in_axes=(None, None, 0)))(y, w, masks)
    assert bool(jnp.all(jnp.isfinite(gy))) and bool(jnp.all(jnp.isfinite(gw)))
    assert bool(jnp.all(gy[1][..., ~masks[1]] == 0))  # masked samples: exactly zero
    cut = (u[:, 2] < np.cos(np.radians(80.0))) | (v[:, 2] < np.cos(np.radians(80.0)))
    assert bool(jnp.any(cut)) and bool(jnp.all(gy[:, ..., cut] == 0))  # cut samples: exactly zero, not NaN
    assert float(jnp.max(jnp.abs(gy[0]))) > 0
    # the same as the gradient of a single fit, eagerly
    g0 = jax.grad(l2)(y, w, masks[0])
    np.testing.assert_allclose(gy[0], g0, rtol=1e-8, atol=1e-14)
