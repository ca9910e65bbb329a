"""The RGL-EPFL benchmarks' split: each file fitted on one 20,000-bin subsample (seed 11) and scored on another
(seed 12), beside the neural BRDF of the same file (``nbrdf_sztrajman2021/rgl_two_nbrdf.zip``, 675 numbers)."""

import jax.numpy as jnp

import polyjax as pj

FILES = ("paper_white_rgb", "satin_rosaline_rgb")


def rgl_split(name: str):
    """``(fit, score, neural)`` of the RGL-EPFL file ``name``: the two subsamples and the neural BRDF's values at
    the scored directions ``(3, n)``."""
    root = pj.data_root()
    path = root / "rgl_epfl" / f"{name}.bsdf"
    fit = pj.data.load_rgl(path, subsample=20000, seed=11)
    score = pj.data.load_rgl(path, subsample=20000, seed=12)
    net = pj.data.load_nbrdf(root / "nbrdf_sztrajman2021" / "rgl_two_nbrdf.zip", name)
    nb = net(score.u, score.v)
    return fit, score, jnp.moveaxis(nb, -1, 0) if nb.shape[-1] == 3 else nb
