"""The reproduction's figures: Figs. 6 and 7 (L2 per CUReT sample), the sphere renderings of Fig. 3, Table 3's
PSNR and Fig. 5, the reciprocity check of Fig. 8, and accuracy vs fit time with its Pareto front."""

from __future__ import annotations

from pathlib import Path

import equinox as eqx
import jax.numpy as jnp
import matplotlib
import numpy as np
from jaxtyping import Array

import baselines
import polyjax as pj
import polyjax.render as pr

from .constants import CURET_POLY, FIG7_POLY, MERL_POLY, TABLE2_IDS
from .experiments import Settings, poly_key
from .report import LABELS, label, md_table

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402 - after choosing the non-interactive backend


class BaselineBRDF(eqx.Module):
    """A fitted baseline as a renderer BRDF: ``params (P,)`` grey or ``(3, P)`` RGB (one lane per channel)."""

    params: Array
    name: str = eqx.field(static=True)

    def __call__(self, u, v):
        model = baselines.get_model(self.name)
        if self.params.ndim == 1:
            return model.evaluate(self.params, u, v)
        return jnp.stack([model.evaluate(p, u, v) for p in self.params], axis=-1)


def renderable(fit, j: int):
    """Lane ``j`` of a polynomial or baseline fit as an RGB renderer BRDF."""
    if isinstance(fit, pj.PolynomialBRDF):
        return pr.rgb_brdf(fit[j])
    return BaselineBRDF(jnp.asarray(np.asarray(fit.params)[j]), fit.name)


def exposure(images, hit, q=99.0, target=0.9) -> float:
    """Exposure (stops) that maps the ``q``-th percentile of the sphere pixels of ``images`` to ``target``."""
    px = np.asarray(images)[..., np.asarray(hit), :]
    level = float(np.percentile(px, q)) if px.size else 0.0
    return float(np.log2(target / level)) if level > 0 else 0.0


def pareto_front(points) -> list[int]:
    """Indices of the points ``(time, error)`` not dominated by another (no other is as fast and more accurate)."""
    order = sorted(range(len(points)), key=lambda i: (points[i][0], points[i][1]))
    front, best = [], np.inf
    for i in order:
        if points[i][1] < best:
            front.append(i)
            best = points[i][1]
    return front


def _l2_plot(path, names, curves, title):
    x = np.arange(len(names))
    fig, ax = plt.subplots(figsize=(12, 5))
    for lbl, y, style in curves:
        ax.plot(x, y, style, ms=3, lw=1, label=lbl)
    ax.set_xticks(x)
    ax.set_xticklabels(names, rotation=90, fontsize=6)
    ax.set_ylabel("L2 (eq. 11)")
    ax.set_title(title)
    ax.legend(fontsize=7, ncol=2)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def figs_67(s: Settings, curet: pj.Measurements, c: dict, out: Path) -> dict:
    """Fig. 6 (every model on the CUReT samples, sorted by Cook-Torrance) and Fig. 7 (the linear models)."""
    names = list(curet.names)
    sort_by = "cook-torrance" if "cook-torrance" in c else s.nonlinear[0]
    order = np.argsort(np.asarray(c[sort_by]["l2"]))
    keys = list(s.nonlinear) + [poly_key(v, p) for v, p in CURET_POLY]
    curves = [(label(k), np.asarray(c[k]["l2"])[order], "-o" if k.startswith("poly:") else "--.") for k in keys]
    _l2_plot(out / "fig6_curet52.png", [names[i] for i in order], curves,
             f"Fig. 6: L2 on {len(names)} isotropic CUReT samples, sorted by {label(sort_by)}")
    keys = [poly_key(*FIG7_POLY[0]), poly_key(*FIG7_POLY[1]), "zernike2", "zernike"]
    order = np.argsort(np.asarray(c[poly_key(*FIG7_POLY[1])]["l2"]))
    curves = []
    for k in keys:
        npar = c[k]["n_params"] if "n_params" in c[k] else (55 if k == "zernike" else 5)
        npar = f" ({npar} par.)"
        curves.append((label(k) + npar, np.asarray(c[k]["l2"])[order], "-o"))
    _l2_plot(out / "fig7_linear_models.png", [names[i] for i in order], curves,
             "Fig. 7: linear models, sorted by Poly. (Lafortune, p = 8)")
    return {"fig6": "fig6_curet52.png", "fig7": "fig7_linear_models.png", "fig6_sorted_by": sort_by}


def fig3(s: Settings, curet: pj.Measurements, c: dict, out: Path, scene) -> dict:
    """Fig. 3: spheres of every CUReT model (rows) on the Table 2 samples (columns)."""
    ids = list(curet.ids)
    pos = [ids.index(i) for i in TABLE2_IDS if i in ids]
    rows_keys = list(s.nonlinear) + ["zernike"] + [poly_key(v, p) for v, p in CURET_POLY]
    g = pr.render_grid([[renderable(c[k]["_fit"], j) for j in pos] for k in rows_keys], scene)
    images = np.asarray(g.images, np.float32)
    ex = exposure(images[rows_keys.index("zernike")], g.hit)
    big = pr.mosaic(images, pad=2, fill=0.0)
    pr.write_exr(out / "fig3_curet_spheres.exr", big)
    pr.write_png(out / "fig3_curet_spheres.png", big, exposure=ex)
    return {"rows": [label(k) for k in rows_keys], "cols": [curet.names[j] for j in pos], "exposure_stops": ex,
            "files": ["fig3_curet_spheres.exr", "fig3_curet_spheres.png"]}


def table3_psnr(s: Settings, m: dict, refs: list, out: Path, scene) -> dict:
    """Table 3's PSNR and Fig. 5: one sphere per MERL material, the neural reference against every model."""
    keys = list(s.nonlinear) + [poly_key(v, p) for v, p in MERL_POLY]
    names = list(s.merl_names)
    rows = [refs] + [[renderable(m[k]["_fit"], j) for j in range(len(names))] for k in keys]
    g = pr.render_grid(rows, scene)
    images = np.asarray(g.images, np.float32)
    hit = np.asarray(g.hit)
    psnr = {k: [] for k in keys}
    exps = []
    for j, n in enumerate(names):
        ex = exposure(images[0, j], hit)
        exps.append(ex)
        stem = "fig5_blue_metallic_paint" if n == "blue-metallic-paint" else f"table3_{n.replace('-', '_')}"
        pr.write_exr(out / f"{stem}.exr", pr.mosaic([[images[0, j]] + list(images[1:, j])], pad=2, fill=0.0))
        scores = pr.comparison_figure(out / f"{stem}.png", images[0, j], list(images[1:, j]), [label(k) for k in keys],
                                      reference_name=f"{n} (neural MERL)", exposure=ex, mask=hit)
        for k in keys:
            psnr[k].append(scores[label(k)])
    return {"exposure_stops": exps, "psnr": psnr, "tonemap": "clip, sRGB, peak 1, sphere pixels only"}


def fig8(s: Settings, m: dict, refs: list, out: Path, scene) -> dict:
    """Fig. 8: reciprocity, orange-paint, Lafortune p = 5: the model and the model with u and v swapped."""
    names = list(s.merl_names)
    j = names.index("orange-paint") if "orange-paint" in names else 0
    b = renderable(m[poly_key("lafortune", 5)]["_fit"], j)
    g = pr.render_grid([[refs[j], b, pr.SwapUV(b)]], scene)
    images = np.asarray(g.images, np.float32)[0]
    ex = exposure(images[0], g.hit)
    pr.write_exr(out / "fig8_reciprocity.exr", pr.mosaic([list(images)], pad=2, fill=0.0))
    scores = pr.comparison_figure(out / "fig8_reciprocity.png", images[0], [images[1], images[2]],
                                  ["Poly. (Lafortune, p = 5)", "same, u and v swapped"],
                                  reference_name=f"{names[j]} (neural MERL)", exposure=ex, mask=np.asarray(g.hit))
    swap = float(np.max(np.abs(images[1] - images[2])))
    return {"material": names[j], "psnr": scores, "max_abs_pixel_difference_swapped": swap,
            "max_pixel": float(images[1].max())}


def accuracy_vs_time(curet_out: dict, merl_out: dict, out: Path) -> dict:
    """Mean L2 against fit time per material of every model, with the Pareto front (PNG and Markdown)."""
    fig, axes = plt.subplots(1, 2, figsize=(13, 5.5))
    result = {}
    md = []
    markers = {"ashikhmin-shirley": "o", "lafortune": "s", "ward": "^"}
    for ax, (ds, recs) in zip(axes, (("CUReT", curet_out), ("MERL (neural)", merl_out))):
        pts = [(k, r["seconds_per_material"], r["mean_l2"]) for k, r in recs.items() if np.isfinite(r["mean_l2"])]
        front = pareto_front([(t, e) for _, t, e in pts])
        for i, (k, t, e) in enumerate(pts):
            if k.startswith("poly:"):
                ax.scatter(t, e, marker=markers[k.split(":")[1]], s=18, c="C0" if i in front else "0.6")
                ax.annotate(k.split(":")[2], (t, e), fontsize=6, xytext=(2, 2), textcoords="offset points")
            else:
                ax.scatter(t, e, marker="*", s=60, c="C3" if i in front else "C1")
                ax.annotate(label(k), (t, e), fontsize=6, xytext=(3, -6), textcoords="offset points")
        fr = sorted((pts[i] for i in front), key=lambda q: q[1])
        ax.plot([q[1] for q in fr], [q[2] for q in fr], "-", c="C2", lw=1, label="Pareto front")
        for var, mk in markers.items():
            ax.scatter([], [], marker=mk, c="C0", label=f"Poly. ({LABELS[var]}), label = p")
        ax.scatter([], [], marker="*", c="C1", label="nonlinear / Zernike")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("fit time per material after compilation (s)")
        ax.set_ylabel("mean L2 (eq. 11)")
        ax.set_title(f"{ds}: {len(next(iter(recs.values()))['l2'])} materials")
        ax.legend(fontsize=7)
        result[ds] = {"points": [{"model": k, "seconds_per_material": t, "mean_l2": e} for k, t, e in pts],
                      "front": [q[0] for q in fr]}
        md.append(f"### {ds}\n\n" + md_table(
            ["model", "time per material (s)", "mean L2"], [[label(k), f"{t:.3g}", f"{e:.5f}"] for k, t, e in fr]))
    fig.tight_layout()
    fig.savefig(out / "accuracy_vs_time.png", dpi=110)
    plt.close(fig)
    (out / "accuracy_vs_time.md").write_text("## Accuracy vs fit time: Pareto front\n\n" + "\n".join(md))
    return result
