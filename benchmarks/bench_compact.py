"""Benchmark: the front of numbers per material against error and fit time of the compact models (issue targets).

Data: the neural-BRDF fits of the MERL materials (Sztrajman et al. 2021): each material fitted on one 20,000-bin
subsample (``load_merl_nbrdf(names, subsample=20000, seed=11)``) and scored on another (``seed=12``). Two metrics
per material: the L2 of equation (11) (80-degree cutoff) and the log metric of :func:`polyjax.log_error` (every
held-out bin above the horizon), each the root mean square over R, G, B (the issue's
``sqrt(sum w r^2 / (3 sum w))``).

Models, at budgets of 9, 16, 33, 64, 128, 256 numbers per material:

- ``compact``: :func:`polyjax.fit_compact`'s rule (3-fold cross-validation on the fitting subsample, the candidate of
  least held-out log error among the candidates within the budget, refitted on all of it). The candidates, to
  bound the compilations (one program per configuration): the basis family's rows alone at ``k = budget // 3`` of
  every budget (configurations ``(k, -1)``), the polynomial family's configurations within ``--poly-budget``
  (33 by default). The
  ``basis`` family is learned leave-one-out: each material's basis is learned from the other materials
  (``benchmarks/learn_compact_basis.py``), never from the material it fits; so its candidates are cross-validated
  here with that basis (the same folds and the same rule as ``polyjax/_compact/select.py``).
- each family alone by the same rule (``basis (LOO)``, ``polynomial``);
- analytic baselines (:func:`baselines.fit`, 16 starts, per channel: 3 x their parameters) and a standard material
  (glTF PBR), fitted on a 5,000-bin part of the fitting subsample;
- the published SGD (33 numbers) and ABC (9) fits, evaluated as published (``baselines.published``);
- the neural BRDF (675 numbers): on MERL the data *are* the neural BRDF (the reference, error 0); on the two
  RGL-EPFL measurements it is a separate model (``rgl_two_nbrdf.zip``) scored against the measurement on held-out
  directions (fit seed 11, score seed 12, 20,000 bins each), beside the compact fit at 33 numbers (shipped basis,
  learned from MERL: another database).

Fit time: the compact refit of the chosen configuration of one material after compilation (median), and the whole
choice (cross-validation of every candidate plus the refit) per material.

Writes ``compact.md``, ``compact.csv``, ``compact_front.png`` and ``compact_spheres.png`` (measured, compact at 33,
SGD: the five materials where the old defaults, Lafortune p = 5, do worst on the log metric) to ``--out``.

Usage: ``POLYJAX_DATA=<data root> python benchmarks/bench_compact.py [--materials 10] [--out DIR]``
"""

import argparse
import csv
import functools
import sys
import time
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

import baselines as bl  # noqa: E402
import polyjax as pj  # noqa: E402
from polyjax._compact.families.basis import BasisFamily  # noqa: E402
from polyjax._compact.select import cross_validate, fold_ids, refit, rgb_errors  # noqa: E402

sys.path.insert(0, str(Path(__file__).parent))
import learn_compact_basis as lcb  # noqa: E402

BUDGETS = (9, 16, 33, 64, 128, 256)
FOLDS = 3
BASELINES = {"cook-torrance": "cook-torrance", "ward": "ward", "glTF PBR (standard)": "gltf-pbr"}
PUBLISHED = {"published SGD": ("sgd", 33), "published ABC": ("abc", 9)}


def errors(values, pred, d):
    """Per material ``(l2, log)``, each the RMS over R, G, B."""
    l2, lg = rgb_errors(values, pred, d.u, d.v, d.weights, jnp.broadcast_to(d.mask, values.shape))
    return np.asarray(l2), np.asarray(lg)


def _held(n):
    return jnp.asarray(fold_ids(n, FOLDS)[None, :] == np.arange(FOLDS)[:, None])


@functools.partial(jax.jit, static_argnames=("k",))
def basis_cv(basis, k, u, v, values, weights, mask, held):
    """:func:`polyjax._compact.select.cross_validate` of the basis family with a basis given as an argument."""
    fam = BasisFamily(basis=basis)

    def one(h):
        params = fam.fit(k, u, v, values, weights, mask & ~h, "log")
        return rgb_errors(values, fam.evaluate(k, params, u, v), u, v, weights, mask & h)

    l2, lg = jax.lax.map(one, held)
    return jnp.sqrt(jnp.mean(l2 ** 2, 0)), jnp.sqrt(jnp.mean(lg ** 2, 0))


@functools.partial(jax.jit, static_argnames=("k",))
def basis_fit_eval(basis, k, u, v, values, weights, mask, us, vs):
    fam = BasisFamily(basis=basis)
    params = fam.fit(k, u, v, values, weights, mask, "log")
    return params, fam.evaluate(k, params, us, vs)


def basis_loo(names, fit, score, max_budget):
    """Per material: CV table ``{k: log}`` with its leave-one-out basis, and per-config held-out predictions."""
    names_all, tables = lcb.material_tables()
    mass = lcb.node_weights()
    held = _held(fit.n_samples)
    ks = sorted({(min(lcb.N_COMPONENTS, b // 3), -1) for b in BUDGETS if b <= max_budget})
    cv, preds, times = [], [], []
    for i, name in enumerate(names):
        basis = jnp.asarray(lcb.learn(tables, mass, names_all, exclude=[name])[0])
        y, m = fit.values[i], jnp.broadcast_to(fit.mask, fit.values[i].shape)
        t0 = time.perf_counter()
        table = {k: float(basis_cv(basis, k, fit.u, fit.v, y, fit.weights, m, held)[1]) for k in ks}
        t_cv = time.perf_counter() - t0
        cv.append(table)
        per = {}
        for k in ks:
            t0 = time.perf_counter()
            params, pred = basis_fit_eval(basis, k, fit.u, fit.v, y, fit.weights, m, score.u, score.v)
            jax.block_until_ready(params)
            per[k] = (pred, time.perf_counter() - t0)
        preds.append(per)
        times.append(t_cv)
        print(f"  basis LOO {name}: cv {t_cv:.1f} s", flush=True)
    return ks, cv, preds, times


def polynomial_cv(names, fit, score, poly_budget, n_poly):
    """Per material (the first ``n_poly``): CV table ``{config: log}`` and held-out predictions of every config."""
    fam = pj.compact_families()["polynomial"]
    held = _held(fit.n_samples)
    configs = fam.configs(poly_budget)
    cv, preds, times = [], [], []
    for i, name in enumerate(names[:n_poly]):
        y, m = fit.values[i], jnp.broadcast_to(fit.mask, fit.values[i].shape)
        t0 = time.perf_counter()
        table = {c: float(cross_validate("polynomial", c, "log", fit.u, fit.v, y, fit.weights, m, held)[1])
                 for c in configs}
        t_cv = time.perf_counter() - t0
        per = {}
        for c in configs:
            t0 = time.perf_counter()
            params = refit("polynomial", c, "log", fit.u, fit.v, y, fit.weights, m)
            jax.block_until_ready(params)
            per[c] = (fam.evaluate(c, params, score.u, score.v), time.perf_counter() - t0)
        cv.append(table)
        preds.append(per)
        times.append(t_cv)
        print(f"  polynomial {name}: cv {t_cv:.1f} s", flush=True)
    return cv, preds, times


def choose(tables, n_numbers, budget):
    """The config of least CV error within ``budget`` across ``tables`` ``[(family, {config: err})]``."""
    best = None
    for family, table in tables:
        for c, e in table.items():
            if n_numbers(family, c) <= budget and np.isfinite(e) and (best is None or e < best[2]):
                best = (family, c, e)
    return best


def n_numbers(family, c):
    return pj.compact_families()[family].n_numbers(c)


def compact_rows(names, score, ks, bcv, bpred, pcv, ppred):
    """``rows[label][budget] = (l2, log, seconds)`` arrays over materials for compact, basis, polynomial."""
    rows = {"compact": {}, "basis (LOO)": {}, "polynomial": {}}
    for budget in BUDGETS:
        for label, fams in (("compact", ("basis", "polynomial")), ("basis (LOO)", ("basis",)),
                            ("polynomial", ("polynomial",))):
            out = []
            for i in range(len(names)):
                tables = [("basis", bcv[i])] if "basis" in fams else []
                if "polynomial" in fams:
                    if i >= len(pcv):
                        out = None
                        break
                    tables.append(("polynomial", pcv[i]))
                best = choose(tables, n_numbers, budget)
                if best is None:
                    out = None
                    break
                pred, secs = (bpred if best[0] == "basis" else ppred)[i][best[1]]
                l2, lg = errors(score.values[i], pred, score)
                out.append((float(l2), float(lg), secs, n_numbers(best[0], best[1]), f"{best[0]} {best[1]}"))
            if out:
                rows[label][budget] = out
    return rows


def published_rows(names, score):
    out = {}
    for label, (name, n) in PUBLISHED.items():
        params = jnp.asarray(bl.published(name, names))
        fn = jax.jit(jax.vmap(jax.vmap(bl.get_model(name).evaluate, in_axes=(0, None, None)),
                              in_axes=(0, None, None)))
        l2, lg = errors(score.values, fn(params, score.u, score.v), score)
        out[label] = (n, l2, lg)
    return out


def baseline_rows(names, fit, score, chunk=20):
    out = {}
    key = jax.random.PRNGKey(0)
    sub_n = min(5000, fit.n_samples)
    for label, name in BASELINES.items():
        preds, ts = [], []
        for s in range(0, len(names), chunk):
            sub = pj.Measurements(u=fit.u[:sub_n], v=fit.v[:sub_n], values=fit.values[s:s + chunk, :, :sub_n],
                                  weights=fit.weights[:sub_n], mask=fit.mask[:sub_n], names=fit.names[s:s + chunk],
                                  channels=fit.channels, axes=fit.axes, source=fit.source)
            t = time.perf_counter()
            f = bl.fit(name, sub, n_starts=16, key=key)
            jax.block_until_ready(f.params)
            ts.append((time.perf_counter() - t) / sub.values.shape[0])
            preds.append(f(score.u, score.v))
        l2, lg = errors(score.values, jnp.concatenate(preds), score)
        out[label] = (3 * bl.get_model(name).n_params, l2, lg, float(np.mean(ts[1:] if len(ts) > 1 else ts)))
        print(f"  {label}: {out[label][3]:.2f} s per material", flush=True)
    return out


def old_default_worst(names, fit, score, n=5):
    """The ``n`` materials where the old defaults (Lafortune p = 5, identity link) do worst on the log metric."""
    f = jax.jit(lambda y: pj.fit_polynomial(fit.u, fit.v, y, variables="lafortune", degree=5,
                                           weights=fit.weights)(score.u, score.v))
    lg = np.array([float(errors(score.values[i], f(fit.values[i]), score)[1]) for i in range(len(names))])
    return [names[i] for i in np.argsort(lg)[::-1][:n]], lg


def rgl_rows():
    """Compact at 33 (shipped basis and polynomial, :func:`polyjax.fit_compact`) and the neural BRDF (675) against
    the two RGL-EPFL measurements on held-out directions."""
    root = pj.data_root()
    zip_path = root / "nbrdf_sztrajman2021" / "rgl_two_nbrdf.zip"
    out = {}
    for name in ("paper_white_rgb", "satin_rosaline_rgb"):
        path = root / "rgl_epfl" / f"{name}.bsdf"
        fit = pj.data.load_rgl(path, subsample=20000, seed=11)
        score = pj.data.load_rgl(path, subsample=20000, seed=12)
        net = pj.data.load_nbrdf(zip_path, name)
        nb = net(score.u, score.v)
        nb = jnp.moveaxis(nb, -1, 0) if nb.shape[-1] == 3 else nb
        t0 = time.perf_counter()
        model = pj.fit_compact(fit, 33)
        t = time.perf_counter() - t0
        c_l2, c_lg = errors(score.values, model(score.u, score.v), score)
        n_l2, n_lg = errors(score.values, nb, score)
        out[name] = dict(compact=(float(c_l2), float(c_lg)), neural=(float(n_l2), float(n_lg)),
                         choice=f"{model.family} {model.config!r} ({model.n_numbers})", seconds=t)
        print(f"  RGL {name}: compact {out[name]['compact']} neural {out[name]['neural']}", flush=True)
    return out


def front_figure(front, path):
    """Median per-material error against numbers per material, both metrics."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(10, 4))
    for j, metric in enumerate(("L2 (eq. 11)", "log metric")):
        ax = axes[j]
        for label, pts in front.items():
            xs = [p[0] for p in pts]
            ys = [p[1 + j] for p in pts]
            ax.plot(xs, ys, "o-" if len(pts) > 1 else "s", label=label)
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("numbers per material")
        ax.set_ylabel(f"median {metric} (held out)")
        ax.grid(True, which="both", alpha=0.3)
    axes[1].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def spheres(worst, names, fit, rows33, out_path):
    """Measured (the neural BRDF), compact at 33 and published SGD spheres of ``worst`` (rows), one PNG."""
    nets = pj.data.load_nbrdf(pj.data.merl_nbrdf_path(), worst)
    sgd = bl.published("sgd", worst)
    grid = []
    for i, name in enumerate(worst):
        sub = fit[names.index(name)]
        m = pj.fit_compact(sub, 33)
        params = jnp.asarray(sgd[i])
        model = bl.get_model("sgd")
        sgd_brdf = pj.render.ParametricBRDF(lambda p, u, v, _m=model: jnp.stack(
            [_m.evaluate(p[c], u, v) for c in range(3)], -1), params)
        grid.append([nets[name], m, sgd_brdf])
    res = pj.render.render_grid(grid, size=64)
    img = np.asarray(res.images)
    rows = [np.concatenate(list(r), axis=1) for r in img]
    pj.render.write_png(out_path, np.concatenate(rows, axis=0))


def targets(rows, pub, names):
    """Lines saying whether each target at 33 numbers is met."""
    if 33 not in rows["compact"]:
        return ["compact at 33: not measured"]
    c = rows["compact"][33]
    l2 = np.array([r[0] for r in c])
    lg = np.array([r[1] for r in c])
    b_l2 = np.minimum(pub["published SGD"][1], pub["published ABC"][1])[:len(c)]
    b_lg = np.minimum(pub["published SGD"][2], pub["published ABC"][2])[:len(c)]
    r2, rl = l2 / b_l2, lg / b_lg
    n = len(c)
    need = int(np.ceil(0.95 * n))
    both = int(np.sum((r2 < 1) & (rl < 1)))
    worst = max(float(r2.max()), float(rl.max()))
    return [f"- 33 numbers, better than the best of SGD and ABC on both metrics: {both} of {n} "
            f"(L2 {int(np.sum(r2 < 1))}, log {int(np.sum(rl < 1))}; median ratio L2 {np.median(r2):.2f}x, "
            f"log {np.median(rl):.2f}x); target "
            f">= {need}: {'MET' if both >= need else 'NOT MET'}",
            f"- no material worse than 2x the best published on either metric: worst {worst:.2f}x "
            f"({names[int(np.argmax(np.maximum(r2, rl)))]}): {'MET' if worst <= 2 else 'NOT MET'}"]


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--materials", type=int, default=100, help="first N MERL materials (default all 100)")
    ap.add_argument("--poly-materials", type=int, default=None,
                    help="materials of the polynomial family's cross-validation (default all --materials)")
    ap.add_argument("--poly-budget", type=int, default=33,
                    help="the polynomial family's candidates: every configuration within this many numbers")
    ap.add_argument("--samples", type=int, default=20000)
    ap.add_argument("--no-baselines", action="store_true", help="skip the nonlinear baselines")
    ap.add_argument("--no-rgl", action="store_true", help="skip the RGL-EPFL measurements")
    ap.add_argument("--no-spheres", action="store_true", help="skip the rendered spheres")
    ap.add_argument("--out", default="compact_out")
    args = ap.parse_args()
    t_all = time.perf_counter()
    names = list(pj.data.MERL_NAMES[: args.materials])
    n_poly = len(names) if args.poly_materials is None else min(args.poly_materials, len(names))
    fit = pj.data.load_merl_nbrdf(names, subsample=args.samples, seed=11)
    score = pj.data.load_merl_nbrdf(names, subsample=args.samples, seed=12)
    print(f"{len(names)} MERL materials; fit on {fit.n_samples} bins (seed 11), scored on {score.n_samples} (seed 12)",
          flush=True)
    ks, bcv, bpred, btimes = basis_loo(names, fit, score, max(BUDGETS))
    pcv, ppred, ptimes = polynomial_cv(names, fit, score, args.poly_budget, n_poly)
    rows = compact_rows(names, score, ks, bcv, bpred, pcv, ppred)
    pub = published_rows(names, score)
    base = {} if args.no_baselines else baseline_rows(names, fit, score)
    worst, _ = old_default_worst(names, fit, score)
    lines = report(args, names, n_poly, rows, pub, base, btimes, ptimes)
    lines += ["", "Targets:"] + targets(rows, pub, names)
    if not args.no_rgl:
        rgl = rgl_rows()
        lines += ["", "RGL-EPFL measurements, held-out directions (fit seed 11, score seed 12, 20,000 bins): "
                  "| material | compact at 33: L2, log | neural BRDF (675): L2, log | ratio L2, log | choice | fit s |",
                  "|---|---|---|---|---|---|"]
        ok = True
        for name, r in rgl.items():
            q = (r["compact"][0] / r["neural"][0], r["compact"][1] / r["neural"][1])
            ok &= max(q) <= 1.25
            lines.append(f"| {name} | {r['compact'][0]:.4f}, {r['compact'][1]:.4f} | {r['neural'][0]:.4f}, "
                         f"{r['neural'][1]:.4f} | {q[0]:.2f}x, {q[1]:.2f}x | {r['choice']} | {r['seconds']:.1f} |")
        lines.append(f"- RGL within 1.25x of the neural BRDF on both metrics at 33: {'MET' if ok else 'NOT MET'}")
    refit_t = [r[2] for r in rows["compact"].get(33, [])]
    if refit_t:
        med = float(np.median(refit_t[1:] if len(refit_t) > 1 else refit_t))
        choice_seconds = np.median(btimes) + (np.median(ptimes) if ptimes else 0)
        lines.append(f"- fit time at 33 (refit of the chosen model, after compilation, median): {med:.3f} s: "
                     f"{'MET' if med < 0.5 else 'NOT MET'} (the whole choice, cross-validation of every candidate "
                     f"up to 256 numbers included: median {choice_seconds:.1f} s per material)")
    lines.append("- worst five materials of the old defaults (Lafortune p = 5, log metric): " + ", ".join(worst))
    lines.append(f"\nTotal run time {time.perf_counter() - t_all:.0f} s.")
    text = "\n".join(lines)
    print(text)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "compact.md").write_text(text + "\n")
    write_csv(out / "compact.csv", names, rows, pub, base)
    front = {label: [(b, float(np.median([r[0] for r in v])), float(np.median([r[1] for r in v])))
                     for b, v in sorted(rows[label].items())] for label in rows if rows[label]}
    for label, (n, l2, lg) in pub.items():
        front[label] = [(n, float(np.median(l2)), float(np.median(lg)))]
    for label, (n, l2, lg, _) in base.items():
        front[label] = [(n, float(np.median(l2)), float(np.median(lg)))]
    front_figure(front, out / "compact_front.png")
    if not args.no_spheres:
        spheres(worst, names, fit, rows.get("compact", {}).get(33), out / "compact_spheres.png")


def report(args, names, n_poly, rows, pub, base, btimes, ptimes):
    lines = [f"{len(names)} MERL materials (neural fits); per material the RMS over R, G, B of the L2 (eq. 11) and "
             f"of the log metric on held-out bins; polynomial family on the first {n_poly} materials. "
             "Neural BRDF (675 numbers): the data themselves (the reference, error 0).", "",
             "| model | numbers / material | median L2 | median log | median refit s | choices (most common) |",
             "|---|---|---|---|---|---|"]
    for label, per in rows.items():
        for budget, v in sorted(per.items()):
            nums = [r[3] for r in v]
            picks = {}
            for r in v:
                picks[r[4].split(" ")[0]] = picks.get(r[4].split(" ")[0], 0) + 1
            lines.append(f"| {label} (budget {budget}) | {int(np.median(nums))} (max {max(nums)}) | "
                         f"{np.median([r[0] for r in v]):.4f} | {np.median([r[1] for r in v]):.4f} | "
                         f"{np.median([r[2] for r in v]):.3f} | {picks} |")
    for label, (n, l2, lg) in pub.items():
        lines.append(f"| {label} | {n} | {np.median(l2):.4f} | {np.median(lg):.4f} | published | |")
    for label, (n, l2, lg, t) in base.items():
        lines.append(f"| {label} | {n} | {np.median(l2):.4f} | {np.median(lg):.4f} | {t:.2f} | |")
    return lines


def write_csv(path, names, rows, pub, base):
    cols = [(f"{label} {b}", [r[i] for r in v]) for label, per in rows.items() for b, v in sorted(per.items())
            for i in (0, 1)]
    cols = [(f"{k} {'l2' if j % 2 == 0 else 'log'}", c) for j, (k, c) in enumerate(cols)]
    for label, vals in list(pub.items()) + list(base.items()):
        cols += [(f"{label} l2", list(vals[1])), (f"{label} log", list(vals[2]))]
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["material"] + [k for k, _ in cols])
        for i, m in enumerate(names):
            w.writerow([m] + [f"{c[i]:.6g}" if i < len(c) else "" for _, c in cols])


if __name__ == "__main__":
    main()
