"""Neural BRDFs of any set in the published format (a zip or folder of Keras .h5 networks), not only MERL's."""

import io
import zipfile

import h5py
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import polyjax as pj

SHAPES = ((6, 21), (21, 21), (21, 3))


def _weights(seed):
    rng = np.random.default_rng(seed)
    out = []
    for shape in SHAPES:
        out.append((0.3 * rng.standard_normal(shape)).astype(np.float32))
        out.append((0.1 * rng.standard_normal(shape[1])).astype(np.float32))
    return out


def _h5_bytes(weights, first_layer: int = 1) -> bytes:
    """A Keras-style weights file: <layer>/<layer>/kernel:0 and bias:0, layers numbered from ``first_layer``."""
    buf = io.BytesIO()
    with h5py.File(buf, "w") as f:
        for i in range(3):
            layer = f"dense_{first_layer + i}"
            f[f"{layer}/{layer}/kernel:0"] = weights[2 * i]
            f[f"{layer}/{layer}/bias:0"] = weights[2 * i + 1]
    return buf.getvalue()


def _half_diff_inputs(u, v):
    """The network's inputs ``(h, d)`` in numpy: the half vector rotated to ``phi_h = 0``, ``(sin theta_h, 0,
    cos theta_h)``, and the difference vector, ``u`` rotated by ``R_y(-theta_h) R_z(-phi_h)``."""
    h = (u + v) / np.linalg.norm(u + v, axis=-1, keepdims=True)
    th, ph = np.arccos(np.clip(h[:, 2], -1.0, 1.0)), np.arctan2(h[:, 1], h[:, 0])
    x = np.cos(ph) * u[:, 0] + np.sin(ph) * u[:, 1]  # R_z(-phi_h) u
    y = -np.sin(ph) * u[:, 0] + np.cos(ph) * u[:, 1]
    d = np.stack([x * np.cos(th) - u[:, 2] * np.sin(th), y, x * np.sin(th) + u[:, 2] * np.cos(th)], axis=-1)
    return np.concatenate([np.stack([np.sin(th), np.zeros_like(th), np.cos(th)], axis=-1), d], axis=-1)


def _reference(weights, u, v):
    """The network of the format (module docstring of polyjax.data._nbrdf), evaluated in numpy."""
    x = _half_diff_inputs(np.asarray(u, np.float64), np.asarray(v, np.float64))
    w1, b1, w2, b2, w3, b3 = (np.asarray(a, np.float64) for a in weights)
    a = np.maximum(x @ w1 + b1, 0)
    a = np.maximum(a @ w2 + b2, 0)
    y = np.expm1(a @ w3 + b3)
    valid = (u[:, 2] > 0) & (v[:, 2] > 0)
    return np.where(valid[:, None], np.maximum(y, 0), 0)


@pytest.fixture()
def rgl_zip(tmp_path):
    """Another set: its own folder name, its own material names, Keras layers numbered from 4 in one file."""
    path = tmp_path / "rgl_isotropic_nbrdf.zip"
    ws = {"acrylic_felt_white": _weights(0), "Paper-Tiger": _weights(1)}
    with zipfile.ZipFile(path, "w") as z:
        z.writestr("rgl_nets/acrylic_felt_white.h5", _h5_bytes(ws["acrylic_felt_white"]))
        z.writestr("rgl_nets/Paper-Tiger.h5", _h5_bytes(ws["Paper-Tiger"], first_layer=4))
        z.writestr("rgl_nets/README.txt", "not a network")
    return path, ws


def _dirs(n=50, seed=3):
    rng = np.random.default_rng(seed)
    th = rng.uniform(0, 1.5, (2, n))
    ph = rng.uniform(-np.pi, np.pi, (2, n))
    u = np.asarray(pj.spherical_to_cartesian(jnp.asarray(th[0]), jnp.asarray(ph[0])))
    v = np.asarray(pj.spherical_to_cartesian(jnp.asarray(th[1]), jnp.asarray(ph[1])))
    return u, v


def test_load_nbrdf_from_any_zip_names_from_its_members(rgl_zip):
    path, ws = rgl_zip
    assert pj.data.nbrdf_names(path) == ("acrylic_felt_white", "Paper-Tiger")
    nets = pj.data.load_nbrdf(path)
    assert list(nets) == ["acrylic_felt_white", "Paper-Tiger"]
    u, v = _dirs()
    for name, net in nets.items():
        assert isinstance(net, pj.data.NeuralBRDF) and net.name == name
        np.testing.assert_allclose(np.asarray(net(u, v)), _reference(ws[name], u, v), rtol=2e-5, atol=1e-7)
    one = pj.data.load_nbrdf(path, "paper_tiger")  # case and -/_ insensitive
    assert one.name == "Paper-Tiger"
    two = pj.data.load_nbrdf(path, ["Paper-Tiger"])
    assert list(two) == ["Paper-Tiger"]


def test_load_nbrdf_from_a_folder(tmp_path):
    folder = tmp_path / "my_networks"
    (folder / "sub").mkdir(parents=True)
    (folder / "sub" / "my-red.h5").write_bytes(_h5_bytes(_weights(5)))
    (folder / "blue.h5").write_bytes(_h5_bytes(_weights(6), first_layer=7))
    nets = pj.data.load_nbrdf(folder)
    assert sorted(nets) == ["blue", "my-red"]
    u, v = _dirs()
    np.testing.assert_allclose(np.asarray(nets["my-red"](u, v)), _reference(_weights(5), u, v), rtol=2e-5, atol=1e-7)


def test_load_spec_nbrdf_path_and_name_gives_measurements_on_the_merl_grid(rgl_zip):
    path, ws = rgl_zip
    d = pj.data.load(f"nbrdf:{path}:Paper-Tiger", subsample=400, seed=2)
    assert d.values.shape == (3, 400) and d.axes == ("channel",) and d.names == ("Paper-Tiger",)
    assert d.channels == ("R", "G", "B")
    ref = _reference(ws["Paper-Tiger"], np.asarray(d.u), np.asarray(d.v))
    np.testing.assert_allclose(np.asarray(d.values), ref.T, rtol=2e-5, atol=1e-7)
    both = pj.data.load(f"nbrdf:{path}", subsample=400, seed=2)
    assert both.values.shape == (2, 3, 400) and both.names == ("acrylic_felt_white", "Paper-Tiger")
    np.testing.assert_allclose(np.asarray(both.values[1]), np.asarray(d.values), rtol=1e-4, atol=1e-7)
    m = pj.fit_polynomial(d, variables="ward", degree=2)
    assert m.l2.shape == (3,) and np.all(np.isfinite(np.asarray(m.l2)))


def test_bad_nbrdf_sets_are_named_errors(rgl_zip, tmp_path):
    path, _ = rgl_zip
    with pytest.raises(pj.data.UnknownMaterialError, match="Paper-Tiger"):
        pj.data.load_nbrdf(path, "paper-tigre")
    empty = tmp_path / "empty.zip"
    with zipfile.ZipFile(empty, "w") as z:
        z.writestr("x/readme.txt", "nothing")
    with pytest.raises(pj.DataFormatError, match="empty.zip.*h5"):
        pj.data.load_nbrdf(empty)
    dup = tmp_path / "dup.zip"
    with zipfile.ZipFile(dup, "w") as z:
        z.writestr("a/red.h5", _h5_bytes(_weights(0)))
        z.writestr("b/red.h5", _h5_bytes(_weights(1)))
    with pytest.raises(pj.DataFormatError, match="red"):
        pj.data.load_nbrdf(dup)
    bad = tmp_path / "bad.zip"
    with zipfile.ZipFile(bad, "w") as z:
        z.writestr("n/thin.h5", _h5_bytes([w[..., :4] if w.ndim == 2 else w for w in _weights(0)]))
    with pytest.raises(pj.DataFormatError, match=r"\(6, 21\).*thin.h5"):
        pj.data.load_nbrdf(bad)
    with pytest.raises(pj.DataNotFoundError, match="nowhere.zip"):
        pj.data.load_nbrdf(tmp_path / "nowhere.zip")


def test_neural_brdf_from_a_set_is_differentiable(rgl_zip):
    path, _ = rgl_zip
    net = pj.data.load_nbrdf(path, "acrylic_felt_white")
    u, v = _dirs(8)
    g = jax.grad(lambda n: jnp.sum(n(u, v)))(net)
    assert np.all(np.isfinite(np.asarray(g.w1))) and np.any(np.asarray(g.w1) != 0)


@pytest.mark.data
def test_merl_zip_through_the_general_loader_matches(data_root):
    zpath = pj.data.merl_nbrdf_path(data_root)
    assert len(pj.data.nbrdf_names(zpath)) == 100
    net = pj.data.load_nbrdf(zpath, "green-latex")
    d = pj.data.load_merl_nbrdf("green-latex", data_root, subsample=300)
    assert d.names == ("green-latex",)
    np.testing.assert_allclose(np.asarray(net(d.u, d.v)).T, np.asarray(d.values), rtol=1e-4, atol=1e-7)
    np.testing.assert_array_equal(np.asarray(pj.data.load(f"nbrdf:{zpath}:green-latex", subsample=300).values),
                                  np.asarray(d.values))
