"""Benchmark: what accuracy the standard material models cost, on the neural-MERL materials and the RGL files.

Claim measured: the L2 of equation (11) and the log metric of every standard model (glTF 2.0 metallic-roughness,
with KHR_materials_specular + _ior, Mitsuba's principled, OpenPBR, UsdPreviewSurface's metallic and specular
workflows), fitted R, G, B jointly (one roughness per material), beside a closed-form polynomial, Cook-Torrance
(one fit per channel) and the published SGD / ABC fits; fit time per material; rendered spheres (measured vs glTF
vs OpenPBR) for a few materials.

The two RGL-EPFL files (``$POLYJAX_DATA/rgl_epfl``, :func:`polyjax.data.read_rgl`'s evaluation) are evaluated at
the same bins and fitted as two more materials after the MERL ones (``--rgl``, on by default): their own table,
since no SGD / ABC fit of them is published.

Same protocol as ``bench_merl100.py``: ``--eval-bins`` (20,000, seed 0) valid MERL bins score every model, the
nonlinear fits use a separate ``--fit-bins`` subsample (seed 1), ``--chunk`` materials per batched call, 16 starts;
fit time per material is the mean over the chunks after the first (so without compilation).

Usage: ``POLYJAX_DATA=<data root> python benchmarks/bench_standard.py [--materials N] [--out DIR]`` (writes
``standard.md``, ``standard.csv``, ``standard.png`` and, after each model, its predictions ``preds.npz``).
"""

import argparse
import time
from pathlib import Path
from types import SimpleNamespace

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

import baselines as bl  # noqa: E402
import polyjax as pj  # noqa: E402
import polyjax.render as pr  # noqa: E402
from benchmarks.bench_merl100 import published_predictions, scores  # noqa: E402
from benchmarks.bench_rgl import FILES as RGL_FILES  # noqa: E402
from benchmarks.bench_rgl import ChannelsLast  # noqa: E402
from polyjax.export._mitsuba_choice import PLUGINS, TOLERANCE, choose_plugin  # noqa: E402

STANDARD = ("gltf-pbr", "gltf-pbr-specular", "principled", "openpbr", "usd-preview", "usd-preview-specular")
PER_CHANNEL = ("cook-torrance",)
POLY = ("log Rus p=4 surface", dict(variables="rusinkiewicz", degree=4, interactions=True, link="log"))
FIGURE = ("alum-bronze", "blue-metallic-paint", "yellow-plastic", "green-latex")
#: the figure's rows: the first three of FIGURE and an RGL file
FIGURE_ROWS = FIGURE[:3] + ("satin_rosaline_rgb",)


def _chunks(dfit, n, chunk):
    for s in range(0, n, chunk):
        yield s, pj.Measurements(u=dfit.u, v=dfit.v, values=dfit.values[s:s + chunk], weights=dfit.weights,
                                 mask=dfit.mask if dfit.mask.ndim == 1 else dfit.mask[s:s + chunk],
                                 names=dfit.names[s:s + chunk], channels=dfit.channels, axes=dfit.axes,
                                 source=dfit.source)


def with_rgl(d, dfit):
    """``d`` and ``dfit`` with the RGL files appended as two more materials, evaluated at the same bins."""
    root = pj.data_root()
    brdfs = [pj.data.read_rgl(pj.data.resolve_rgl_path(f, root)) for f in RGL_FILES]

    def grow(m):
        values = jnp.concatenate([m.values, jnp.stack([jnp.asarray(b(m.u, m.v)) for b in brdfs])])
        return pj.Measurements(u=m.u, v=m.v, values=values, weights=m.weights, mask=m.mask,
                               names=tuple(m.names) + RGL_FILES, channels=m.channels, axes=m.axes, source=m.source)

    return grow(d), grow(dfit), dict(zip(RGL_FILES, brdfs))


def fit_models(d, dfit, n, chunk, preds, times, fits, out_dir: Path, models=STANDARD + PER_CHANNEL):
    for name in models:
        out, ts, bad, params = [], [], 0, []
        for _, sub in _chunks(dfit, n, chunk):
            t = time.perf_counter()
            f = bl.fit(name, sub, n_starts=16)
            f.params.block_until_ready()
            ts.append((time.perf_counter() - t) / sub.values.shape[0])
            bad += int(np.sum(~np.asarray(f.success)))
            out.append(f(d.u, d.v))
            params.append(np.asarray(f.params))
        preds[name] = jnp.concatenate(out)
        fits[name] = np.concatenate(params)
        times[name] = float(np.mean(ts[1:])) if len(ts) > 1 else ts[0]
        print(f"  {name}: {times[name]:.2f} s per material (first chunk {ts[0] * chunk:.1f} s incl. compile); "
              f"{bad} of {3 * n} lanes not converged  [load {open('/proc/loadavg').read().split()[0]}]", flush=True)
        np.savez(out_dir / "preds.npz", **{k: np.asarray(v) for k, v in preds.items()},
                 **{f"params {k}": v for k, v in fits.items()})


def fit_poly(d, n, preds, times):
    label, opts = POLY
    fit = jax.jit(lambda y, w: pj.fit_polynomial(d.u, d.v, y, weights=w, **opts))
    out, ts = [], []
    for i in range(n):
        t = time.perf_counter()
        m = fit(d.values[i], d.weights)
        m.coefficients.block_until_ready()
        ts.append(time.perf_counter() - t)
        out.append(m(d.u, d.v))
    preds[label] = jnp.stack(out)
    times[label] = float(np.median(ts[1:])) if n > 1 else ts[0]


def _fit_brdf(name, params):
    p = jnp.asarray(params)
    z = jnp.zeros((3,), jnp.int32)
    return bl.BaselineFit(params=p, raw=p, l2=jnp.zeros(3), status=z, steps=z, success=z == 0,
                          start_l2=jnp.zeros((3, 1)), start_status=z[:, None], best_start=z,
                          at_limit=jnp.zeros(p.shape, bool), name=name)


def figure(names, fits, out: Path, rgl: dict, size=96):
    """Spheres under one point light: the neural MERL BRDF (or the RGL file), its glTF and OpenPBR fits (tone-mapped
    x/(1+x))."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    cam = pr.Camera(eye=(0.0, 0.0, 5.0), width=size, height=size, fov_deg=30.0)
    shown = [m for m in FIGURE_ROWS if m in names]
    fig, axes = plt.subplots(len(shown), 3, figsize=(6, 2 * len(shown)), squeeze=False)
    for r, mat in enumerate(shown):
        i = names.index(mat)
        measured = ChannelsLast(rgl[mat]) if mat in rgl else pj.data.load_nbrdf(mat)
        brdfs = [measured, _fit_brdf("gltf-pbr", fits["gltf-pbr"][i]), _fit_brdf("openpbr", fits["openpbr"][i])]
        label = "measured (RGL)" if mat in rgl else "measured (neural)"
        for c, (brdf, title) in enumerate(zip(brdfs, (label, "glTF", "OpenPBR"))):
            scene = pr.Scene(cam, [pr.Sphere(brdf)], [pr.PointLight((3.0, 2.0, 4.0), 30.0)])
            img = np.asarray(pr.render(scene, dtype=jnp.float64).image)
            axes[r, c].imshow(np.clip(img / (1 + img), 0, 1) ** (1 / 2.2))
            axes[r, c].set_xticks([])
            axes[r, c].set_yticks([])
            axes[r, c].set_title(f"{mat}: {title}" if c == 0 else title, fontsize=7)
    fig.tight_layout()
    fig.savefig(out, dpi=120)


N_PAR = {"gltf-pbr": "3 + 2", "gltf-pbr-specular": "3 + 4", "principled": "3 + 3", "cook-torrance": "3 x 4",
         "openpbr": "3 x 2 + 4", "usd-preview": "3 + 3", "usd-preview-specular": "3 x 2 + 1", POLY[0]: "3 x 70",
         "published sgd": "3 x 10", "published abc": "3 x 5", "roughconductor": "3 x 2 + 1",
         "roughplastic": "3 + 2"}


def table(names, d, preds, times) -> str:
    rows = ["| model | P | median L2 (eq. 11) | median log metric | beats glTF (L2) | fit time / material (s) |",
            "|---|---|---|---|---|---|"]
    l2 = {k: scores(d.values, p, d)[0] for k, p in preds.items()}
    lg = {k: scores(d.values, p, d)[1] for k, p in preds.items()}
    n_par = N_PAR
    for k in preds:
        t = f"{times[k]:.3f}" if k in times else "-"
        beats = int(np.sum(l2[k] < l2["gltf-pbr"])) if "gltf-pbr" in l2 else 0
        rows.append(f"| {k} | {n_par.get(k, '')} | {np.median(l2[k]):.4g} | {np.median(lg[k]):.4g} | "
                    f"{beats} / {len(names)} | {t} |")
    return "\n".join(rows), l2, lg


def plugin_choices(l2) -> str:
    """How often ``polyjax export --to mitsuba-xml`` (its rule, :func:`choose_plugin`) would write each plugin."""
    chosen = [choose_plugin({k: l2[k][i] for k in PLUGINS}) for i in range(len(l2["principled"]))]
    counts = ", ".join(f"{k} {chosen.count(k)}" for k in PLUGINS)
    return f"Mitsuba XML plugin chosen (the simplest within {TOLERANCE:g} of principled's L2): {counts}"


def rgl_table(d, preds, rgl_rows) -> str:
    """Per RGL file and model: L2 of equation (11) (and relative to the zero BRDF's) and the log metric."""
    vals = d.values[rgl_rows]
    zero = scores(vals, jnp.zeros_like(vals), d)[0]
    rows = ["| model | " + " | ".join(f"{f}: L2 (/ zero) | {f}: log" for f in RGL_FILES) + " |",
            "|---|" + "---|---|" * len(RGL_FILES)]
    for k, p in preds.items():
        if k.startswith("published"):
            continue
        l2, lg = scores(vals, p[rgl_rows], d)
        rows.append(f"| {k} | " + " | ".join(f"{a:.4g} ({a / z:.3f}) | {b:.4g}" for a, b, z in zip(l2, lg, zero))
                    + " |")
    return "\n".join(rows)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--materials", type=int, default=100, help="N MERL materials, the figure's first (default 100)")
    ap.add_argument("--eval-bins", type=int, default=20000)
    ap.add_argument("--fit-bins", type=int, default=5000)
    ap.add_argument("--chunk", type=int, default=10)
    ap.add_argument("--out", default="standard_out")
    ap.add_argument("--no-rgl", dest="rgl", action="store_false", help="leave the RGL files out")
    ap.add_argument("--models", default=",".join(STANDARD + PER_CHANNEL), help="comma-separated models to fit "
                    "(the figure needs gltf-pbr and openpbr)")
    args = ap.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    names = list(dict.fromkeys(FIGURE + tuple(pj.data.MERL_NAMES)))[: args.materials]  # the figure's first
    d = pj.data.load_merl_nbrdf(names, subsample=args.eval_bins, seed=0)
    dfit = pj.data.load_merl_nbrdf(names, subsample=args.fit_bins, seed=1)
    n_merl = len(names)
    rgl = {}
    if args.rgl:
        d, dfit, rgl = with_rgl(d, dfit)
        names = list(d.names)
    print(f"{n_merl} MERL materials + {len(rgl)} RGL files; scored on {d.u.shape[0]} bins (seed 0), nonlinear fits on "
          f"{dfit.u.shape[0]} (seed 1), chunks of {args.chunk}; load {open('/proc/loadavg').read().split()[:3]}",
          flush=True)
    preds, times, fits = {}, {}, {}
    fit_poly(d, len(names), preds, times)
    fit_models(d, dfit, len(names), args.chunk, preds, times, fits, out, tuple(args.models.split(",")))
    merl = SimpleNamespace(u=d.u, v=d.v, values=d.values[:n_merl], weights=d.weights)
    mpreds = {f"published {k}": published_predictions(k, names[:n_merl], d) for k in ("sgd", "abc")}
    mpreds.update({k: p[:n_merl] for k, p in preds.items()})
    md, l2, lg = table(names[:n_merl], merl, mpreds, times)
    if all(k in l2 for k in PLUGINS):
        md += "\n\n" + plugin_choices(l2)
    if rgl:
        md += "\n\nRGL files:\n\n" + rgl_table(d, preds, np.arange(n_merl, len(names)))
    preds = mpreds
    names = names[:n_merl]
    (out / "standard.md").write_text(md + "\n")
    with open(out / "standard.csv", "w") as fh:
        fh.write("material," + ",".join(f"l2 {k}" for k in preds) + "," + ",".join(f"log {k}" for k in preds) + "\n")
        for i, n in enumerate(names):
            fh.write(n + "," + ",".join(f"{l2[k][i]:.6g}" for k in preds) + ","
                     + ",".join(f"{lg[k][i]:.6g}" for k in preds) + "\n")
    if "gltf-pbr" in fits and "openpbr" in fits:
        figure(list(d.names), fits, out / "standard.png", rgl)
    print(md)
    print(f"total {time.perf_counter() - t0:.0f} s; load average {open('/proc/loadavg').read().split()[:3]}")


if __name__ == "__main__":
    main()
