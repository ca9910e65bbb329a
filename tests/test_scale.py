"""Per-lane directions (each texel its own directions and PCA), streamed in blocks of lanes; sharded fits on 8
simulated devices; a 2-process ``jax.distributed`` fit written shard by shard."""

import os

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from jax.test_util import check_grads

import polyjax as pj


def _dirs(rng, shape):
    d = rng.normal(size=shape + (3,))
    d[..., 2] = np.abs(d[..., 2]) + 0.3
    return d / np.linalg.norm(d, axis=-1, keepdims=True)


def _texels(seed=0, h=3, w=5, k=40):
    rng = np.random.default_rng(seed)
    u, v = _dirs(rng, (h, w, k)), _dirs(rng, (h, w, k))
    vals = rng.uniform(0.1, 1.0, size=(h, w, 3, k))
    return u, v, vals


def test_per_lane_directions_equal_lane_alone():
    u, v, vals = _texels()
    model = pj.fit_polynomial(u, v, vals, "lafortune", degree=[2, 3], lane_block=4)  # 4 lanes: 2 texels a block
    assert model.coefficients.shape == (2, 3, 5, 3, 7) and model.rotation.shape == (2, 3, 5, 3, 2, 2)
    for i in range(3):
        for j in range(5):
            alone = pj.fit_polynomial(u[i, j], v[i, j], vals[i, j], "lafortune", degree=[2, 3])
            for field in ("coefficients", "l2", "mean", "rotation", "centre", "halfwidth", "condition"):
                np.testing.assert_allclose(getattr(model, field)[:, i, j], getattr(alone, field), rtol=1e-12,
                                           atol=1e-12, err_msg=field)
            np.testing.assert_array_equal(model.status[:, i, j], alone.status)
    # the texel's own directions: its model reproduces its own fit there, not another texel's
    np.testing.assert_allclose(model[1][2, 4](u[2, 4], v[2, 4]), alone[1](u[2, 4], v[2, 4]), rtol=1e-12)


def test_per_lane_directions_and_weights_any_block():
    rng = np.random.default_rng(1)
    u, v = _dirs(rng, (7, 30)), _dirs(rng, (7, 30))
    y, w = rng.uniform(size=(7, 30)), rng.uniform(0.5, 2.0, size=(7, 30))
    mask = rng.uniform(size=(7, 30)) > 0.1
    ref = [pj.fit_polynomial(u[i], v[i], y[i], "ward", degree=3, weights=w[i], mask=mask[i]) for i in range(7)]
    for block in (1, 3, 7, 100):
        m = pj.fit_polynomial(u, v, y, "ward", degree=3, weights=w, mask=mask, lane_block=block)
        np.testing.assert_allclose(m.coefficients, np.stack([r.coefficients for r in ref]), rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(m.l2, np.stack([r.l2 for r in ref]), rtol=1e-12)


def test_per_lane_directions_bad_shapes():
    u, v, vals = _texels()
    with pytest.raises(pj.InputError, match="leading part"):
        pj.fit_polynomial(u[:2], v[:2], vals)
    with pytest.raises(pj.InputError, match=r"weights: expected shape \(40,\) or \(3, 5, 40\)"):
        pj.fit_polynomial(u, v, vals, weights=np.ones((3, 5, 3, 40)))
    with pytest.raises(pj.InputError, match="lane_block"):
        pj.fit_polynomial(u, v, vals, lane_block=0)


def test_per_lane_directions_differentiate():
    """``check_grads`` (forward and reverse, against finite differences) w.r.t. values, weights and the per-lane
    directions, through the closed-form solve's own rule, inside the loop over blocks of lanes."""
    u, v, vals = _texels(2, 2, 2, 25)
    w = np.random.default_rng(3).uniform(0.5, 2.0, size=(2, 2, 25))

    # compiled: under check_grads' tracers the fit takes the same (traced-input) path as under jit, and one compiled
    # program per derivative replaces a dispatch per operation
    @jax.jit
    def f(vals, w, u):
        m = pj.fit_polynomial(u, v, vals, "lafortune", degree=2, weights=w, lane_block=2)
        return m.l2 + jnp.sum(m.coefficients[..., :3], axis=-1)

    check_grads(f, (vals, w, u), order=1, modes=("fwd", "rev"), atol=1e-5, rtol=1e-5)
    g = jax.jit(jax.grad(lambda vals: f(vals, w, u).sum()))(vals)
    assert np.all(np.isfinite(g)) and np.abs(g).max() > 0


_SHARDED = r'''
import json, sys
import jax, numpy as np
jax.config.update("jax_enable_x64", True)
from jax.sharding import NamedSharding, PartitionSpec as P
import polyjax as pj

mesh = jax.make_mesh((8,), ("x",))  # what users get: Explicit axes by default
rng = np.random.default_rng(0)
def dirs(shape):
    d = rng.normal(size=shape + (3,)); d[..., 2] = np.abs(d[..., 2]) + 0.3
    return d / np.linalg.norm(d, axis=-1, keepdims=True)
u, v, y = dirs((16, 4, 30)), dirs((16, 4, 30)), rng.uniform(0.1, 1.0, size=(16, 4, 3, 30))
w = rng.uniform(0.5, 2.0, size=(16, 4, 30))
us, vs, ys, ws = (jax.device_put(a, NamedSharding(mesh, P("x"))) for a in (u, v, y, w))
out = {"axis_types": str(mesh.axis_types)}
cases = {
    "per_lane_directions": (dict(u=us, v=vs, values=ys, weights=ws), dict(u=u, v=v, values=y, weights=w)),
    "shared_directions": (dict(u=u[0, 0], v=v[0, 0], values=ys), dict(u=u[0, 0], v=v[0, 0], values=y)),
    "per_lane_weights": (dict(u=u[0, 0], v=v[0, 0], values=ys, weights=jax.device_put(
        np.broadcast_to(w[:, :, None], y.shape), NamedSharding(mesh, P("x")))),
        dict(u=u[0, 0], v=v[0, 0], values=y, weights=np.broadcast_to(w[:, :, None], y.shape))),
}
for name, (sharded, plain) in cases.items():
    ms = pj.fit_polynomial(**sharded, variables="lafortune", degree=[2, 3])
    m0 = pj.fit_polynomial(**plain, variables="lafortune", degree=[2, 3])
    diff = max(float(np.max(np.abs(np.asarray(getattr(ms, f)) - np.asarray(getattr(m0, f)))))
               for f in ("coefficients", "l2", "mean", "rotation", "centre", "halfwidth"))
    shard = ms.coefficients.sharding
    out[name] = dict(diff=diff, devices=len(shard.device_set), spec=str(shard.spec),
                     shard_shape=list(shard.shard_shape(ms.coefficients.shape)),
                     l2_devices=len(ms.l2.sharding.device_set), same_status=bool(np.all(
                         np.asarray(ms.status) == np.asarray(m0.status))))
# under jit, traced sharded inputs
f = jax.jit(lambda u, v, y: pj.fit_polynomial(u, v, y, "ward", degree=3).coefficients)
c = f(us, vs, ys)
out["jit"] = dict(diff=float(np.max(np.abs(np.asarray(c) - np.asarray(
    pj.fit_polynomial(u, v, y, "ward", degree=3).coefficients)))), devices=len(c.sharding.device_set))
print("RESULT " + json.dumps(out))
'''


def _run(code, env_extra, timeout=600):
    import json
    import subprocess
    import sys
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    env = dict(os.environ, PYTHONPATH=str(root) + os.pathsep + os.environ.get("PYTHONPATH", ""), **env_extra)
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=timeout, env=env,
                       cwd=root)
    assert p.returncode == 0, p.stderr[-3000:]
    line = [ln for ln in p.stdout.splitlines() if ln.startswith("RESULT ")][-1]
    return json.loads(line[len("RESULT "):])


def test_sharded_fit_on_8_devices():
    flags = os.environ.get("XLA_FLAGS", "") + " --xla_force_host_platform_device_count=8"  # the tests' own kept
    out = _run(_SHARDED, {"XLA_FLAGS": flags.strip()})
    assert "Explicit" in out["axis_types"]
    for name in ("per_lane_directions", "shared_directions", "per_lane_weights"):
        r = out[name]
        assert r["diff"] <= 1e-12, (name, r)
        assert r["devices"] == 8 and r["l2_devices"] == 8 and r["same_status"], (name, r)
        assert r["spec"].startswith("P(None, 'x'") and r["shard_shape"][:2] == [2, 2], (name, r)
    assert out["jit"]["diff"] <= 1e-12 and out["jit"]["devices"] == 8


_CAPTURE = r'''
import jax.numpy as jnp
def phong(kd, ks, n):
    def f(u, v):
        r = jnp.stack([-u[..., 0], -u[..., 1], u[..., 2]], -1)
        c = jnp.clip(jnp.sum(r * v, -1), 0.0, 1.0) ** n
        return jnp.asarray(kd) / jnp.pi + jnp.asarray(ks) * c[..., None]
    return f
MATERIALS = [phong((0.6, 0.3, 0.2), (0.2, 0.2, 0.2), 8.0), phong((0.1, 0.4, 0.6), (0.5, 0.5, 0.5), 20.0)]
H, W, K = 8, 6, 24
'''

_PROCESS = _CAPTURE + r'''
import sys
from polyjax import svbrdf
pid, port, out = int(sys.argv[1]), int(sys.argv[2]), sys.argv[3]
svbrdf.initialize(f"localhost:{port}", 2, pid)
import jax
jax.config.update("jax_enable_x64", True)
import polyjax as pj

def load_rows(start, stop):  # this process's part of the texture, and nothing else
    cap = svbrdf.simulate_capture(MATERIALS, H, W, n_lights=K, rows=slice(start, stop))
    u, v, b, w = cap.observations()
    return dict(u=u, v=v, values=b, weights=w)

model = svbrdf.fit_rows_distributed(load_rows, H, "lafortune", 3)
svbrdf.write_texture_shards(out, model, formats=("npz", "exr"))
print("RESULT " + __import__("json").dumps(dict(
    process=jax.process_index(), count=jax.process_count(), devices=len(model.coefficients.sharding.device_set),
    rows=list(svbrdf.local_rows(H)), local=len(model.coefficients.addressable_shards),
    global_shape=list(model.coefficients.shape))))
'''


def test_two_process_distributed_fit_writes_its_shards(tmp_path):
    import json
    import subprocess
    import sys
    from pathlib import Path

    from polyjax import svbrdf

    root = Path(__file__).resolve().parents[1]
    port = svbrdf.free_port()
    env = dict(os.environ, PYTHONPATH=str(root) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    # one device per process (no simulated devices); the tests' other XLA flags kept
    env["XLA_FLAGS"] = " ".join(f for f in env.get("XLA_FLAGS", "").split() if "device_count" not in f)
    procs = [subprocess.Popen([sys.executable, "-c", _PROCESS, str(i), str(port), str(tmp_path / "tex")],
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env, cwd=root)
             for i in range(2)]
    outs = []
    try:
        for p in procs:
            so, se = p.communicate(timeout=600)
            assert p.returncode == 0, se[-3000:]
            outs.append(json.loads([ln for ln in so.splitlines() if ln.startswith("RESULT ")][-1][7:]))
    finally:
        for p in procs:
            if p.poll() is None:
                p.kill()
    assert [o["count"] for o in outs] == [2, 2] and [o["devices"] for o in outs] == [2, 2]
    assert [o["rows"] for o in outs] == [[0, 4], [4, 8]] and [o["local"] for o in outs] == [1, 1]
    meta = json.loads((tmp_path / "tex" / "manifest.json").read_text())
    assert [s["file"] for s in meta["shards"]] == ["rows-0-4.npz", "rows-4-8.npz"]
    assert [s["process"] for s in meta["shards"]] == [0, 1]
    # each process wrote its half; together they equal one single-process fit
    ns = {}
    exec(_CAPTURE, ns)
    cap = svbrdf.simulate_capture(ns["MATERIALS"], ns["H"], ns["W"], n_lights=ns["K"])
    ref = svbrdf.fit_capture(cap, "lafortune", 3)
    got = svbrdf.read_texture_shards(tmp_path / "tex")
    for f in ("coefficients", "l2", "mean", "rotation", "centre", "halfwidth"):
        np.testing.assert_allclose(getattr(got, f), getattr(ref, f), rtol=1e-12, atol=1e-12, err_msg=f)
    np.testing.assert_array_equal(got.status, ref.status)
    half = svbrdf.read_texture_shards(tmp_path / "tex", rows=(4, 8))
    np.testing.assert_allclose(half.coefficients, ref.coefficients[4:], rtol=1e-12, atol=1e-12)
    # the EXR shards each process wrote beside its npz: the same texture within float64-as-two-float32 precision
    assert [s["files"]["exr"] for s in meta["shards"]] == ["rows-0-4.exr", "rows-4-8.exr"]
    exr = svbrdf.read_texture_shards(tmp_path / "tex", format="exr")
    np.testing.assert_allclose(exr.coefficients, got.coefficients, rtol=2.0**-48, atol=0)
    np.testing.assert_array_equal(exr.status, ref.status)
