"""Benchmark: the compact model families against the published SGD and ABC fits, at every size (issue 36).

Protocol: each of the 100 MERL materials (neural-BRDF fits, Sztrajman et al. 2021) is fitted on a 20,000-bin
subsample (``load_merl_nbrdf(name, subsample=20000, seed=11)``) and scored on another (``seed=12``) with two metrics:
the L2 of equation (11) (``pj.l2_error``, 80-degree cutoff, mean over R, G, B) and the log metric
(``pj.log_error``, no cutoff, solid-angle weights; ``sqrt(mean over R, G, B of log_error^2)``). Ratios are to the
better of the published SGD (33 numbers) and ABC (9) fits on that material and metric, evaluated as
``benchmarks/bench_merl100.py`` evaluates them. The ``basis`` family of every MERL material is LEAVE-ONE-OUT: its
basis is learned from the other 99 materials (``learn_compact_basis.py``'s PCA, asserted to exclude the material).

Also: both RGL-EPFL files (real measurements; fit on ``load_rgl(subsample=20000, seed=11)``, scored on ``seed=12``)
against the neural BRDF of the same material (675 numbers), with the shipped basis (learned from MERL only);
CUReT (61 materials, 205 samples each, one channel) and Cornell (3 files) fitted on half the samples and scored
on the other half (log metric, weights 1), basis against polynomial; and the fit time of one MERL material on
20,000 samples after compilation (median of 10).

``--skew 1,3,8`` adds the ``skew`` family (the basis with ``m`` non-reciprocal rows, each ``m`` given) to the MERL
table (leave-one-out bases, and each skew configuration's held-out errors over the basis family's per material) and
to the RGL table.

Usage: ``POLYJAX_DATA=<data root> python benchmarks/bench_compact_families.py [--materials N] [--sizes 9,16,33]
[--skip merl,rgl,other,time] [--skew 1,3,8]``
"""

import argparse
import os
import sys
import time
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).parents[1]))

import polyjax as pj  # noqa: E402
from benchmarks.bench_merl100 import published_predictions  # noqa: E402
from benchmarks.learn_compact_basis import material_tables, node_weights, transform  # noqa: E402
from polyjax.internal import COMPACT_FAMILIES, CompactBasisFamily, CompactSkewFamily  # noqa: E402

SIZES = (9, 16, 33, 64, 128, 256)
RGL = ("paper_white_rgb", "satin_rosaline_rgb")
BASIS_ROWS = 86  # leave-one-out bases: the mean and 85 components (256 numbers)


def scores(values, pred, d, mask=None):
    """Per material: mean over channels of the L2 (eq. 11), and sqrt(mean over channels of log_error^2)."""
    l2 = pj.l2_error(values, pred, d.u, d.v, d.weights, mask=mask)
    lg = pj.log_error(values, pred, d.u, d.v, d.weights, mask=mask)
    return np.asarray(jnp.mean(l2, -1)), np.asarray(jnp.sqrt(jnp.mean(lg**2, -1)))


class LeaveOneOut:
    """The PCA of ``learn_compact_basis.learn`` without one material, for every material, from one Gram matrix
    of the 3 x 100 transformed, mass-weighted tables (the same basis as ``learn(..., exclude=(name,))``)."""

    def __init__(self, names, tables, mass):
        self.names, self.sw = list(names), np.sqrt(mass)
        self.y = (transform(tables) * self.sw).reshape(-1, tables.shape[-1])
        self.gram = self.y @ self.y.T

    def family(self, name, rows=BASIS_ROWS):
        keep = np.array([r for r in range(self.y.shape[0]) if self.names[r // 3] != name])
        yk = self.y[keep]
        mean = yk.mean(0)
        h = np.eye(len(keep)) - 1.0 / len(keep)
        e, vecs = np.linalg.eigh(h @ self.gram[np.ix_(keep, keep)] @ h)
        e, vecs = e[::-1][: rows - 1], vecs[:, ::-1][:, : rows - 1]
        comps = (vecs.T @ (yk - mean)) / np.sqrt(e)[:, None]
        basis = np.concatenate([mean[None], comps]) / self.sw
        fam = CompactBasisFamily(basis, [n for n in self.names if n != name])
        assert name not in fam.trained_on, f"the basis of {name} was learned from it"
        return fam

    def skew(self, name, rows=BASIS_ROWS):
        """The ``skew`` family on the same leave-one-out basis."""
        fam = self.family(name, rows)
        return CompactSkewFamily(np.asarray(fam.basis), fam.trained_on)


def poly_config(size):
    """The polynomial family's configuration at a size: Rusinkiewicz with interactions, the largest degree."""
    fam = COMPACT_FAMILIES["polynomial"]
    ok = [c for c in fam.configs(size) if c[0] == "rusinkiewicz" and c[2]]
    return max(ok, key=lambda c: c[1]) if ok else None


def configs(size, hybrids=False, skew=()):
    """``{label: (family, config)}`` at a size: the polynomial, the basis alone, (``hybrids``) the basis with
    the polynomial terms of degree 1 and 2 of the grid's coordinates, and the ``skew`` family with each number ``m``
    of non-reciprocal rows in ``skew`` (the largest ``k`` within the size)."""
    out = {"polynomial": ("polynomial", poly_config(size))}
    if size // 3 <= BASIS_ROWS:
        out["basis"] = ("basis", (size // 3, -1))
    for d, terms in ((1, 4), (2, 10)):
        if hybrids and size // 3 > terms:
            out[f"basis+poly{d}"] = ("basis", (size // 3 - terms, d))
    for m in skew:
        if m <= size // 3 - m <= BASIS_ROWS:
            out[f"skew{m}"] = ("skew", (size // 3 - m, m))
    return {k: c for k, c in out.items() if c[1] is not None}


def merl_runs(names, sizes, fit, score, skew=()):
    """``{(label, size): (predictions (m, 3, n), n_numbers)}`` on the score bins, leave-one-out bases (the basis
    family, and the ``skew`` family with each number of non-reciprocal rows in ``skew``, on the same basis)."""
    loo = LeaveOneOut(*material_tables(), node_weights())
    preds = {}
    for i, name in enumerate(names):
        fam = loo.family(name)
        fams = {"basis": fam, "skew": CompactSkewFamily(np.asarray(fam.basis), fam.trained_on)}
        for size in sizes:
            for label, (family, k) in configs(size, skew=skew).items():
                if family in fams:
                    c = fams[family].fit(k, fit.u, fit.v, fit.values[i], fit.weights, None, "log")
                    preds.setdefault((label, size), []).append(fams[family].evaluate(k, c, score.u, score.v))
        if i % 10 == 9:
            print(f"  basis: {i + 1} materials", flush=True)
    out = {key: (jnp.stack(p), 3 * (key[1] // 3)) for key, p in preds.items()}
    poly = COMPACT_FAMILIES["polynomial"]
    for size in sizes:
        c = configs(size)["polynomial"][1]
        m = poly.fit(c, fit.u, fit.v, fit.values, fit.weights, None, "log")
        out[("polynomial", size)] = (poly.evaluate(c, m, score.u, score.v), poly.n_numbers(c))
    return out


def merl_table(names, sizes, skew=()):
    fit = pj.data.load_merl_nbrdf(names, subsample=20000, seed=11)
    score = pj.data.load_merl_nbrdf(names, subsample=20000, seed=12)
    pub = {n: scores(score.values, published_predictions(n, names, score), score) for n in ("sgd", "abc")}
    best_l2 = np.minimum(pub["sgd"][0], pub["abc"][0])
    best_lg = np.minimum(pub["sgd"][1], pub["abc"][1])
    rows = ["| family | size | numbers | L2 median ratio | L2 better | L2 worst (material) | log median ratio | "
            "log better | log worst (material) | better on both |", "|---|---|---|---|---|---|---|---|---|---|"]
    errors = {}
    for (family, size), (pred, n_num) in sorted(merl_runs(names, sizes, fit, score, skew).items()):
        l2, lg = errors[family, size] = scores(score.values, pred, score)
        r2, rl = l2 / best_l2, lg / best_lg
        rows.append(f"| {family} | {size} | {n_num} | {np.median(r2):.3f} | {np.sum(r2 < 1)} | {r2.max():.2f} "
                    f"({names[int(r2.argmax())]}) | {np.median(rl):.3f} | {np.sum(rl < 1)} | {rl.max():.2f} "
                    f"({names[int(rl.argmax())]}) | {np.sum((r2 < 1) & (rl < 1))} |")
    return rows + skew_against_basis(errors)


def skew_against_basis(errors):
    """Per material, each skew configuration's held-out errors over the basis family's at the same size."""
    rows = ["", "| skew / basis (same size) | size | L2: median, max, materials better | "
                "log: median, max, materials better |", "|---|---|---|---|"]
    for (label, size), (l2, lg) in sorted(errors.items()):
        if label.startswith("skew") and ("basis", size) in errors:
            b2, blg = errors["basis", size]
            r2, rl = l2 / b2, lg / blg
            rows.append(f"| {label} | {size} | {np.median(r2):.3f}, {r2.max():.2f}, {np.sum(r2 < 1)} | "
                        f"{np.median(rl):.3f}, {rl.max():.2f}, {np.sum(rl < 1)} |")
    return rows if len(rows) > 4 else []


def rgl_table(sizes, skew=()):
    root = pj.data_root()
    nets = pj.data.load_nbrdf(root / "nbrdf_sztrajman2021" / "rgl_two_nbrdf.zip")
    rows = ["| file | model | numbers | L2 | L2 / neural | log | log / neural |", "|---|---|---|---|---|---|---|"]
    for name in RGL:
        fit = pj.data.load_rgl(name, subsample=20000, seed=11)
        score = pj.data.load_rgl(name, subsample=20000, seed=12)
        net = next(n for k, n in nets.items() if k.replace("-", "_").startswith(name))
        neural = jnp.moveaxis(net(score.u, score.v), -1, 0)
        nl2, nlg = scores(score.values, neural, score, score.mask)
        rows.append(f"| {name} | neural BRDF | 675 | {nl2:.4f} | 1 | {nlg:.4f} | 1 |")
        for size in sizes:
            for label, (family, c) in configs(size, hybrids=True, skew=skew).items():
                fam = COMPACT_FAMILIES[family]
                l2, lg = fit_and_score(fam, c, fit, score)
                rows.append(f"| {name} | {label} {c} | {fam.n_numbers(c)} | {l2:.4f} | {l2 / nl2:.2f} | "
                            f"{lg:.4f} | {lg / nlg:.2f} |")
    return rows


def fit_and_score(fam, config, fit, score):
    """Both metrics (L2, log) on ``score`` of ``fam``'s ``config`` fitted for the log metric on ``fit``."""
    p = fam.fit(config, fit.u, fit.v, fit.values, fit.weights, fit.mask, "log")
    return scores(score.values, fam.evaluate(config, p, score.u, score.v), score, score.mask)


def halves(d, seed=0):
    """The samples split in two halves (fit, score) by a seeded permutation."""
    n = d.u.shape[0]
    perm = np.random.default_rng(seed).permutation(n)
    a, b = np.sort(perm[: n // 2]), np.sort(perm[n // 2:])
    pick = [pj.Measurements(u=d.u[i], v=d.v[i], values=d.values[..., i], weights=d.weights[..., i],
                            mask=d.mask[..., i], names=d.names, channels=d.channels, axes=d.axes, source=d.source)
            for i in (a, b)]
    return pick


def other_table(sizes):
    rows = ["| data | family | numbers per 3 channels | median log error (held-out half) | median L2 |",
            "|---|---|---|---|---|"]
    curet = pj.data.load_curet()
    curet = pj.Measurements(u=curet.u, v=curet.v, values=curet.values[:, None], weights=curet.weights,
                            mask=curet.mask, names=curet.names, channels=("Y",), axes=("material", "channel"),
                            source=curet.source)
    cornell = pj.data.load_cornell(["acryl_blue", "cayman", "garnet_red"])
    for label, d in (("CUReT (61)", curet), ("Cornell (3)", cornell)):
        fit, score = halves(d)
        for size in sizes:
            for label_, (family, c) in configs(size, hybrids=True).items():
                fam = COMPACT_FAMILIES[family]
                l2, lg = fit_and_score(fam, c, fit, score)
                rows.append(f"| {label} | {label_} {c} | {fam.n_numbers(c)} | {np.median(lg):.4f} | "
                            f"{np.median(l2):.4f} |")
    return rows


def time_table(sizes):
    d = pj.data.load_merl_nbrdf("gold-metallic-paint", subsample=20000, seed=11)
    rows = ["| family | config | numbers | fit s (compiled, median of 10) | first call s |", "|---|---|---|---|---|"]
    for size in sizes:
        for label, (family, c) in configs(size, hybrids=True).items():
            fam = COMPACT_FAMILIES[family]
            fn = jax.jit(lambda u, v, y, w, f=fam, c=c: f.fit(c, u, v, y, w, None, "log"))
            ts = []
            for _ in range(11):
                t = time.perf_counter()
                jax.block_until_ready(fn(d.u, d.v, d.values, d.weights))
                ts.append(time.perf_counter() - t)
            rows.append(f"| {label} | {c} | {fam.n_numbers(c)} | {np.median(ts[1:]):.3f} | {ts[0]:.2f} |")
    return rows


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--materials", type=int, default=100)
    ap.add_argument("--sizes", default=",".join(map(str, SIZES)))
    ap.add_argument("--merl-sizes", default=None, help="sizes of the MERL table (default --sizes)")
    ap.add_argument("--skip", default="", help="comma-separated parts to skip: merl, rgl, other, time")
    ap.add_argument("--skew", default="", help="comma-separated numbers m of non-reciprocal rows of the skew family "
                                               "to measure in the MERL and RGL tables (e.g. 1,3,8; none by default)")
    args = ap.parse_args()
    skew = tuple(int(m) for m in args.skew.split(",") if m)
    sizes = [int(s) for s in args.sizes.split(",")]
    skip = set(args.skip.split(","))
    names = list(pj.data.MERL_NAMES[: args.materials])
    print(f"load average at start: {open('/proc/loadavg').read().split()[:3]}; devices {jax.devices()}", flush=True)
    t0 = time.perf_counter()
    merl_sizes = sizes if args.merl_sizes is None else [int(s) for s in args.merl_sizes.split(",")]
    parts = (("merl", lambda: merl_table(names, merl_sizes, skew)), ("rgl", lambda: rgl_table(sizes, skew)),
             ("other", lambda: other_table([s for s in sizes if s <= 33])), ("time", lambda: time_table(sizes)))
    for label, part in parts:
        if label not in skip:
            print("\n".join(["", f"### {label}", "", *part()]), flush=True)
    print(f"\ntotal {time.perf_counter() - t0:.0f} s; load average at end: {open('/proc/loadavg').read().split()[:3]}")


if __name__ == "__main__":
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    main()
