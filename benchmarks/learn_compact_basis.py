"""Learn the principal-component basis of the compact ``basis`` family from the 100 MERL materials.

Each material's neural BRDF (Sztrajman et al. 2021) is evaluated at the nodes of the folded Rusinkiewicz grid
(``polyjax/_compact/families/_grid.py``); a node below the horizon takes the value of the nearest valid
configuration along ``theta_d`` (so the tables extend continuously past the horizon, where interpolation reads
them near grazing). The tables are transformed, ``g = log(1 + K f)`` (``K`` of the family), and a weighted PCA of
the ``3 x materials`` rows gives the basis: the weighted mean first, then the principal components, each node
weighted by the solid-angle mass of the MERL bins that interpolate from it (a 200,000-bin sample). The shipped
file holds ``N_COMPONENTS`` rows in float32; leave-one-out bases for benchmarks are made by :func:`learn` with
``exclude``.

Usage: ``POLYJAX_DATA=<data root> python benchmarks/learn_compact_basis.py [--out polyjax/_compact/data/basis.npz]``
"""

import argparse
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

import polyjax as pj  # noqa: E402
from polyjax._compact.families import _grid  # noqa: E402
from polyjax._compact.families.basis import K_TRANSFORM, N_COMPONENTS  # noqa: E402
from polyjax.internal import write_atomically  # noqa: E402

_EDGE = 0.02  # the smaller cosine of a node moved back above the horizon


def valid_node_directions(shape=_grid.SHAPE):
    """Node directions, each below-horizon node moved along ``theta_d`` to where its smaller cosine is ``_EDGE``."""
    a, b, c = (np.linspace(0.0, 1.0, n) for n in shape)
    th, td, pd = np.meshgrid(np.minimum(a * a, 88.0 / 90.0) * np.pi / 2, b * np.pi / 2, c * np.pi / 2, indexing="ij")
    big_a, big_b = np.cos(th), np.cos(pd) * np.sin(th)
    r = np.hypot(big_a, big_b)
    td_max = np.maximum(np.arccos(np.minimum(_EDGE / r, 1.0)) - np.arctan2(big_b, big_a), 0.0)
    td = np.minimum(td, td_max)
    return pj.data.rusinkiewicz_to_directions(th, td, pd)


def node_tables(nets) -> np.ndarray:
    """``(m, 3, nodes)`` BRDF values of neural BRDFs (a dict) at the grid's nodes (extended past the horizon)."""
    u, v = (jnp.asarray(x.reshape(-1, 3)) for x in valid_node_directions())
    return np.stack([np.asarray(net(u, v)).T for net in nets.values()])


def node_weights(n_bins: int = 200_000) -> np.ndarray:
    """Solid-angle mass of MERL bins at each node (trilinear shares of a seeded sample of valid bins)."""
    d = pj.data.load_merl_nbrdf("white-paint", subsample=n_bins, seed=99)
    idx, w = _grid.interpolation(d.u, d.v)
    mass = np.zeros(int(np.prod(_grid.SHAPE)))
    np.add.at(mass, np.asarray(idx).ravel(), (np.asarray(w) * np.asarray(d.weights)[:, None]).ravel())
    return mass / mass.sum() + 1e-4 / mass.size


def transform(f):
    return np.log1p(K_TRANSFORM * np.maximum(f, 0.0))


def learn(tables, mass, names, exclude=(), n_components: int = N_COMPONENTS):
    """Basis ``(n_components, nodes)``: the mean of the transformed tables of every material not in
    ``exclude``, then their weighted principal components; and the names it was learned from."""
    keep = [i for i, n in enumerate(names) if n not in set(exclude)]
    x = transform(tables[keep]).reshape(-1, tables.shape[-1])
    sw = np.sqrt(mass)
    mean = x.mean(0)
    _, _, vt = np.linalg.svd((x - mean) * sw, full_matrices=False)
    basis = np.concatenate([mean[None], vt[: n_components - 1] / sw])
    return basis, tuple(names[i] for i in keep)


def material_tables():
    names = list(pj.data.MERL_NAMES)
    nets = pj.data.load_nbrdf(pj.data.merl_nbrdf_path(), names)
    return names, node_tables(nets)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=str(Path(__file__).parents[1] / "polyjax/_compact/data/basis.npz"))
    args = ap.parse_args()
    names, tables = material_tables()
    mass = node_weights()
    basis, used = learn(tables, mass, names)
    write_atomically(Path(args.out), lambda tmp: np.savez_compressed(
        tmp, basis=basis.astype(np.float32), shape=np.array(_grid.SHAPE), k=np.array(K_TRANSFORM),
        materials=np.array(used)))
    print(f"basis {basis.shape} from {len(used)} materials -> {args.out}")


if __name__ == "__main__":
    main()
