"""Fewer compiled programs: host data reaches the device without compiling, eager evaluations are one program each,
the renderer's primary rays serve every BRDF, and the Zernike design's tabulated radial polynomials are the
polynomials of its definition."""

import contextlib
import logging
from math import factorial

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import baselines
import polyjax as pj
import polyjax.render as pr
from polyjax.internal import cast_concrete, device_array
from tests._problems import random_hemisphere


@contextlib.contextmanager
def compiled_names():
    """The names of the programs XLA compiles inside the block (JAX's compile log)."""
    names: list[str] = []

    class Grab(logging.Handler):
        def emit(self, record):
            msg = record.getMessage()
            if msg.startswith("Finished XLA compilation of "):
                names.append(msg.split(" of ", 1)[1].split(" in ")[0])

    handler = Grab(level=logging.DEBUG)
    loggers = [logging.getLogger(n) for n in ("jax._src.interpreters.pxla", "jax._src.dispatch")]
    saved = [(lg.level, lg.propagate) for lg in loggers]
    for lg in loggers:
        lg.addHandler(handler)
        lg.setLevel(logging.DEBUG)
    try:
        with jax.log_compiles(True):
            yield names
    finally:
        for lg, (level, propagate) in zip(loggers, saved):
            lg.removeHandler(handler)
            lg.setLevel(level)
            lg.propagate = propagate


@pytest.mark.parametrize("host", [np.arange(12.0).reshape(3, 4), np.arange(5, dtype=np.float32), [1, 2, 3],
                                  np.array([True, False]), [[0.5, 1.5]], np.int32(7)])
@pytest.mark.parametrize("dtype", [None, jnp.float32, jnp.float64])
def test_device_array_is_jnp_asarray_without_compiling(host, dtype):
    want = jnp.asarray(host, dtype)
    with compiled_names() as names:
        got = device_array(host, dtype)
    assert names == []
    assert got.dtype == want.dtype and got.shape == want.shape and got.weak_type == want.weak_type
    np.testing.assert_array_equal(np.asarray(got), np.asarray(want))


def test_device_array_and_cast_pass_traced_and_device_arrays_through():
    x = jnp.arange(3.0)
    assert device_array(x) is x
    assert cast_concrete(x, x.dtype) is x
    y = cast_concrete(x, jnp.float32)
    assert y.dtype == jnp.float32 and np.array_equal(np.asarray(y), [0.0, 1.0, 2.0])
    # under a trace both are jnp operations (differentiable)
    assert float(jax.grad(lambda a: jnp.sum(cast_concrete(a, jnp.float32) * device_array(a)))(2.0)) == 4.0


def test_model_evaluation_and_selection_are_one_program_each():
    u, v = random_hemisphere(300, seed=3)
    rng = np.random.default_rng(0)
    model = pj.fit_polynomial(u, v, rng.random((2, 3, 300)), degree=[2, 3])
    uu, vv = random_hemisphere(77, seed=4)
    with compiled_names() as names:
        f = model(uu, vv)
    assert f.shape == (2, 2, 3, 77)
    assert names == ["jit(_evaluate)"], names
    with compiled_names() as names:  # the same shapes again: nothing compiled
        model(uu + 0.0, vv)
    assert names == []
    lane_indices = (0, (1, 1), slice(0, 1), np.int64(1), (slice(None), 1), -1, (0, 1, 2))
    for i, index in enumerate(lane_indices + ((Ellipsis, 0), (0, None))):  # the last two reach into the fields
        with compiled_names() as names:
            picked = model[index]
        assert len(names) <= 1
        plain = jax.tree.map(lambda a, index=index: a[index], model)
        assert all(np.array_equal(a, b) for a, b in zip(jax.tree.leaves(picked), jax.tree.leaves(plain))), index
        if i < len(lane_indices):
            np.testing.assert_array_equal(picked(uu, vv), plain(uu, vv))
    lanes = model[np.array([0, 1, 1])]  # an array index: taken field by field
    assert lanes.batch_shape == (3, 2, 3)


def test_primary_rays_compiled_once_for_every_brdf():
    scene = pr.sphere_scene(size=23)  # a size no other test renders
    a = pr.render(scene).image  # compiles the primary rays of this camera (unless compiled before)
    other = pr.Scene(scene.camera, [pr.Sphere(pr.Phong(0.1, 0.5, 40.0))], scene.lights)
    with compiled_names() as second:
        b = pr.render(other).image
    assert second  # a new BRDF family: its shading compiles ...
    assert "jit(_primary_rays)" not in second  # ... the rays do not
    assert float(jnp.max(jnp.abs(a - b))) > 1e-3  # and the images do differ


def _radial_reference(n, m, r2):
    """``R_n^m(rho) / rho^m`` summed term by term in Python floats (the definition)."""
    return sum((-1) ** k * factorial(n - k) / (factorial(k) * factorial((n + m) // 2 - k)
                                               * factorial((n - m) // 2 - k)) * r2 ** ((n - m) // 2 - k)
               for k in range((n - m) // 2 + 1))


@pytest.mark.parametrize("order, tol", [(2, 1e-15), (8, 1e-13), (20, 1e-9)])
def test_zernike_design_matches_its_definition(order, tol):
    u, v = random_hemisphere(40, seed=5)
    got = np.asarray(baselines.zernike_design(u, v, order))
    ux, uy, ru = (np.asarray(a) for a in baselines.disk_point(u))
    vx, vy, rv = (np.asarray(a) for a in baselines.disk_point(v))
    z = (ux + 1j * uy) * (vx - 1j * vy)
    want = np.stack([0.5 * (_radial_reference(n, m, ru) * _radial_reference(n2, m, rv)
                            + _radial_reference(n2, m, ru) * _radial_reference(n, m, rv)) * (z ** m).real
                     for (m, n, n2) in baselines.zernike_terms(order)], axis=-1)
    assert got.shape == want.shape == (40, baselines.n_zernike_terms(order))
    np.testing.assert_allclose(got, want, rtol=0, atol=tol)


def test_per_lane_directions_checks_after_their_compiled_preparation():
    """Directions ``(G, n, 3)`` shared by the lanes of each group: NaN values are refused (naming them), masked when
    asked for if every lane of a group has them at the same samples (else refused), and bad weights refused."""
    (u0, v0), (u1, v1) = random_hemisphere(60, seed=6), random_hemisphere(60, seed=7)
    u, v = np.stack([u0, u1]), np.stack([v0, v1])  # 2 groups
    y = np.random.default_rng(2).random((2, 3, 60))  # 3 lanes per group
    with pytest.raises(pj.InputError, match="values"):
        pj.fit_polynomial(u, v, np.where(np.arange(60) == 5, np.nan, y), degree=2)
    bad = y.copy()
    bad[0, 1, 7] = np.nan  # one lane of group 0 only
    with pytest.raises(pj.InputError, match="same samples"):
        pj.fit_polynomial(u, v, bad, degree=2, nonfinite="mask")
    with pytest.raises(pj.InputError, match="weights"):
        pj.fit_polynomial(u, v, y, degree=2, weights=-np.ones((2, 60)))
    same = y.copy()
    same[0, :, 7] = np.nan  # every lane of group 0 at sample 7
    masked = pj.fit_polynomial(u, v, same, degree=2, nonfinite="mask")
    keep = np.ones((2, 60), bool)
    keep[0, 7] = False
    want = pj.fit_polynomial(u, v, np.where(np.isnan(same), 0.0, same), degree=2, mask=keep)
    np.testing.assert_allclose(masked.coefficients, want.coefficients, rtol=1e-12, atol=1e-14)
    np.testing.assert_array_equal(masked.n_used, want.n_used)
    full = pj.fit_polynomial(u, v, y, degree=2)
    assert np.all(np.asarray(full.n_used)[0] - np.asarray(masked.n_used)[0] <= 1)
    np.testing.assert_array_equal(np.asarray(full.n_used)[1], np.asarray(masked.n_used)[1])
