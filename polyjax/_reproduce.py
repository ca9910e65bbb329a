r"""``polyjax reproduce``: the paper's Tables 1-4 and Figs. 3, 5, 6, 7, 8, plus accuracy vs fit time.

Every number is computed in the run and written to the results folder (``--out``):

- ``table1.md`` .. ``table4.md``: ours | paper | ratio (paper values: the ``PAPER_TABLE*`` constants);
- ``fig3_curet_spheres``, ``fig5_blue_metallic_paint``, ``fig8_reciprocity``, ``table3_<material>``
  (``.exr`` linear, ``.png`` sRGB), ``fig6_curet52.png``, ``fig7_linear_models.png``;
- ``accuracy_vs_time.png`` / ``.md``: mean L2 against fit time per material of every model and
  polynomial degree ``p`` (three variable sets) with the Pareto front; scipy ``least_squares`` and a
  numpy ``lstsq`` loop on the same data, timed in the same run;
- ``results.json``: every number, the settings, software versions and machine; ``report.md``: all tables.

Conventions: L2 is the paper's equation (11) (80-degree cutoff, solid-angle weights), per lane
(CUReT: the RGB average of each sample; MERL and Cornell: per channel, then averaged over R, G, B).
MERL data are the neural-BRDF fits of the MERL materials evaluated on the MERL grid; the nonlinear
models are fitted to a reproducible random subsample of it and their L2 is evaluated on the same
grid as the polynomial models. Fit times are per material, after compilation (best of ``repeats``
calls of one batched fit of all materials), compilation reported separately.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array

from ._cli import PAPER_TABLE1
from ._references import numpy_design, numpy_lstsq_l2, scipy_best_l2

# ------------------------------------------------------------------------------------------------
# the paper's numbers (Ozturk, Kurt, Bilgili, Gungor, Computers & Graphics 32 (2008) 149-158)

#: Table 2: L2 on Felt (1), Orange peel (55), Quarry tile (25), Slate_a (33), Slate_b (34).
PAPER_TABLE2: dict[str, tuple[float, ...]] = {
    "ashikhmin-shirley": (0.0190, 0.0217, 0.0165, 0.0121, 0.0223),
    "blinn-phong": (0.0518, 0.0626, 0.0369, 0.0196, 0.0586),
    "cook-torrance": (0.0229, 0.0213, 0.0136, 0.0107, 0.0236),
    "lafortune": (0.0170, 0.0245, 0.0117, 0.0070, 0.0184),
    "oren-nayar": (0.0571, 0.0740, 0.0429, 0.0249, 0.0711),
    "ward": (0.0385, 0.0420, 0.0241, 0.0124, 0.0383),
    "ward-duer": (0.0238, 0.0219, 0.0137, 0.0109, 0.0243),
    "zernike": (0.0087, 0.0126, 0.0069, 0.0059, 0.0068),
    "poly:ashikhmin-shirley:5": (0.0090, 0.0206, 0.0098, 0.0063, 0.0114),
    "poly:lafortune:7": (0.0126, 0.0227, 0.0093, 0.0062, 0.0165),
    "poly:ward:7": (0.0228, 0.0277, 0.0122, 0.0092, 0.0266),
}
TABLE2_IDS = (1, 55, 25, 33, 34)

#: Table 3: (L2, PSNR dB) on beige-fabric, blue-metallic-paint, dark-blue-paint, green-latex, orange-paint,
#: yellow-plastic (the order of polyjax.data.TABLE3_MATERIALS).
PAPER_TABLE3: dict[str, tuple[tuple[float, float], ...]] = {
    "ashikhmin-shirley": ((0.0053, 46.043), (0.0150, 39.043), (0.0043, 42.330), (0.0040, 43.286), (0.0038, 46.710), (0.0071, 39.321)),
    "blinn-phong": ((0.0104, 37.683), (0.0228, 31.570), (0.0109, 34.671), (0.0064, 38.841), (0.0100, 39.573), (0.0143, 36.288)),
    "cook-torrance": ((0.0080, 42.629), (0.0172, 39.589), (0.0035, 43.425), (0.0037, 43.255), (0.0037, 46.789), (0.0068, 39.544)),
    "lafortune": ((0.0075, 42.113), (0.0132, 38.099), (0.0056, 42.353), (0.0036, 44.434), (0.0061, 45.504), (0.0086, 39.709)),
    "oren-nayar": ((0.0105, 37.706), (0.0540, 26.654), (0.0129, 33.120), (0.0076, 38.507), (0.0119, 38.228), (0.0153, 35.654)),
    "ward": ((0.0101, 38.055), (0.0146, 34.977), (0.0091, 36.824), (0.0052, 40.540), (0.0085, 41.683), (0.0130, 36.976)),
    "ward-duer": ((0.0093, 38.563), (0.0171, 38.899), (0.0056, 39.619), (0.0037, 43.249), (0.0059, 41.680), (0.0103, 37.663)),
    "poly:ashikhmin-shirley:3": ((0.0038, 48.104), (0.0331, 34.291), (0.0064, 42.514), (0.0029, 47.707), (0.0049, 47.429), (0.0082, 43.864)),
    "poly:lafortune:5": ((0.0056, 45.083), (0.0314, 35.535), (0.0060, 42.472), (0.0029, 46.507), (0.0049, 47.244), (0.0089, 41.809)),
    "poly:ward:5": ((0.0064, 45.574), (0.0347, 31.333), (0.0040, 41.873), (0.0026, 49.557), (0.0039, 45.523), (0.0061, 43.561)),
}

#: Table 4: average fitting time (s) per material, 52 isotropic CUReT samples, Pentium D 2.66 GHz, 2 GB.
PAPER_TABLE4: dict[str, float] = {
    "ashikhmin-shirley": 0.33175, "blinn-phong": 0.38900, "cook-torrance": 0.34725, "lafortune": 0.36540,
    "oren-nayar": 0.15596, "ward": 0.29025, "ward-duer": 0.26925, "poly:ashikhmin-shirley:5": 0.01567,
    "poly:lafortune:7": 0.01565, "poly:ward:7": 0.01565,
}

#: Section 6 / Fig. 6: in how many of the 52 CUReT samples each polynomial model has the lowest L2
#: of it and the seven nonlinear models.
PAPER_LOWEST_COUNTS: dict[str, int] = {"poly:ashikhmin-shirley:5": 45, "poly:lafortune:7": 40, "poly:ward:7": 23}

VARIABLE_SETS = ("ashikhmin-shirley", "lafortune", "ward")
CURET_POLY = (("ashikhmin-shirley", 5), ("lafortune", 7), ("ward", 7))  # Tables 2 and 4, Figs. 3 and 6
MERL_POLY = (("ashikhmin-shirley", 3), ("lafortune", 5), ("ward", 5))  # Table 3, Figs. 4 and 5
FIG7_POLY = (("lafortune", 2), ("lafortune", 8))  # Fig. 7: the linear models on CUReT


def poly_configs(degrees, required) -> list[tuple[str, int]]:
    """The ``(variables, p)`` fits of a run: every variable set at every degree of the sweep, plus ``required``."""
    return sorted({(var, p) for var in VARIABLE_SETS for p in degrees} | set(required))
LABELS = {
    "ashikhmin-shirley": "Ashikhmin-Shirley", "blinn-phong": "Blinn-Phong", "cook-torrance": "Cook-Torrance",
    "lafortune": "Lafortune", "oren-nayar": "Oren-Nayar", "ward": "Ward", "ward-duer": "Ward-Duer",
    "zernike": "Zernike (order 8)", "zernike2": "Zernike (order 2)",
}


def poly_key(variables: str, p: int) -> str:
    return f"poly:{variables}:{p}"


def label(key: str) -> str:
    if key.startswith("poly:"):
        _, var, p = key.split(":")
        return f"Poly. ({LABELS[var]}, p = {p})"
    return LABELS.get(key, key)


@dataclass
class Settings:
    """What a run computes; ``quick`` shrinks every axis."""

    quick: bool = False
    curet_ids: tuple[int, ...] = ()
    nonlinear: tuple[str, ...] = ()
    n_starts: int = 16
    merl_names: tuple[str, ...] = ()
    merl_fit_subsample: int = 20000
    merl_eval_subsample: int | None = None
    degrees: tuple[int, ...] = tuple(range(1, 11))  # the accuracy-vs-time sweep; the tables' fits always run
    size: int = 128
    repeats: int = 3
    scipy_materials: int = 8
    numpy_merl_materials: int = 1
    seed: int = 0
    extra: dict = field(default_factory=dict)

    @classmethod
    def make(cls, quick: bool) -> "Settings":
        import baselines
        import polyjax as pj

        if quick:
            return cls(
                quick=True, curet_ids=TABLE2_IDS, nonlinear=("lafortune",), n_starts=4,
                merl_names=("blue-metallic-paint", "orange-paint"), merl_fit_subsample=2000,
                merl_eval_subsample=20000, degrees=(), size=24, repeats=1, scipy_materials=1,
            )
        return cls(
            quick=False, curet_ids=tuple(pj.data.ISOTROPIC_52), nonlinear=tuple(baselines.NONLINEAR_MODELS),
            merl_names=tuple(pj.data.TABLE3_MATERIALS),
        )


# ------------------------------------------------------------------------------------------------
# small helpers


def _block(x):
    import jax

    return jax.block_until_ready(x)


def timed(fn, repeats: int):
    """``(result, first_call_s, best_s)``: the first call compiles; the best of ``repeats`` later calls is the time."""
    t0 = time.perf_counter()
    out = _block(fn())
    first = time.perf_counter() - t0
    best = np.inf
    for _ in range(max(1, repeats)):
        t0 = time.perf_counter()
        out = _block(fn())
        best = min(best, time.perf_counter() - t0)
    return out, first, best


def _finite(x) -> float | None:
    x = float(x)
    return x if np.isfinite(x) else None


def _fmt(x, nd=4) -> str:
    if x is None or not np.isfinite(x):
        return "-"
    return f"{x:.{nd}f}"


def _md_table(header: list[str], rows: list[list[str]]) -> str:
    out = ["| " + " | ".join(header) + " |", "|" + "|".join(["---"] * len(header)) + "|"]
    out += ["| " + " | ".join(r) + " |" for r in rows]
    return "\n".join(out) + "\n"


def _ratio(a, b):
    return None if a is None or b is None or not b else a / b


# ------------------------------------------------------------------------------------------------
# rendering adapters


class _BaselineBRDF(eqx.Module):
    """A fitted baseline as a renderer BRDF: ``params (P,)`` grey or ``(3, P)`` RGB (one lane per channel)."""

    params: Array
    name: str = eqx.field(static=True)

    def __call__(self, u, v):
        import baselines

        model = baselines.get_model(self.name)
        if self.params.ndim == 1:
            return model.evaluate(self.params, u, v)
        return jnp.stack([model.evaluate(p, u, v) for p in self.params], axis=-1)


def _exposure(images, hit, q=99.0, target=0.9) -> float:
    """Exposure (stops) that maps the ``q``-th percentile of the sphere pixels of ``images`` to ``target``."""
    px = np.asarray(images)[..., np.asarray(hit), :]
    level = float(np.percentile(px, q)) if px.size else 0.0
    return float(np.log2(target / level)) if level > 0 else 0.0


# ------------------------------------------------------------------------------------------------
# the run


class Run:
    """Holds data, fits and results of one reproduction run."""

    def __init__(self, settings: Settings, out: Path, root=None, progress=None):
        self.s = settings
        self.out = out
        self.root = root
        self.bar = progress
        self.res: dict = {"settings": asdict(settings), "step_seconds": {}}
        self.fits: dict = {}
        self._t = time.perf_counter()

    def step(self, what: str):
        """Mark the end of a step: its wall time (compilation included) goes to ``results.json``."""
        now = time.perf_counter()
        self.res["step_seconds"][what] = round(now - self._t, 3)
        self._t = now
        if self.bar is not None:
            self.bar.set_description(what)
            self.bar.update(1)

    # -- data ------------------------------------------------------------------------------------
    def load(self):
        import jax

        import polyjax as pj

        s = self.s
        self.curet = pj.data.load_curet(self.root, list(s.curet_ids))
        self.merl = pj.data.load_merl_nbrdf(list(s.merl_names), self.root, subsample=s.merl_eval_subsample, seed=s.seed)
        self.merl_fit = pj.data.load_merl_nbrdf(list(s.merl_names), self.root, subsample=s.merl_fit_subsample,
                                                seed=s.seed + 1)
        jax.block_until_ready((self.merl.values, self.merl_fit.values))
        self.res["data"] = {
            "curet": {"source": self.curet.source, "ids": list(self.curet.ids), "names": list(self.curet.names),
                      "n_samples": int(self.curet.values.shape[-1])},
            "merl": {"source": self.merl.source, "names": list(s.merl_names), "n_eval": int(self.merl.values.shape[-1]),
                     "n_fit_nonlinear": int(self.merl_fit.values.shape[-1]),
                     "eval_subsample": s.merl_eval_subsample, "fit_subsample": s.merl_fit_subsample,
                     "seeds": {"eval": s.seed, "fit": s.seed + 1}},
        }

    # -- Table 1 ---------------------------------------------------------------------------------
    def table1(self):
        import polyjax as pj

        deg = list(range(1, 7))
        q = pj.data.load_curet(self.root, [25])
        lq = np.asarray(pj.fit_polynomial(q, variables="lafortune", degree=deg).l2)[:, 0]
        cay = {}
        for ch in ("luminance", "rgb", "xyz"):
            m = pj.data.load("cornell:cayman", self.root, channels=ch)
            l2 = np.asarray(pj.fit_polynomial(m, variables="lafortune", degree=deg).l2)  # (6, C)
            cay[ch] = {"channels": list(m.channels), "l2": l2.tolist(), "mean": l2.mean(-1).tolist()}
        m = pj.data.load("cornell:cayman", self.root, channels="luminance")
        zero = float(np.asarray(pj.l2_error(m.values, 0.0 * m.values, m.u, m.v, weights=m.weights)).ravel()[0])
        cay["luminance_l2_of_zero_model"] = zero
        cay["n_samples"] = int(m.values.shape[-1])
        self.res["table1"] = {
            "degrees": deg, "n_params_kp1": [2 * p + 1 for p in deg], "n_params_paper_column": [2 * p + 5 for p in deg],
            "quarry_tile": lq.tolist(), "cayman": cay, "cayman_channel_used": "luminance",
            "paper": {k: list(v) for k, v in PAPER_TABLE1.items()},
        }

    # -- CUReT fits ------------------------------------------------------------------------------
    def curet_fits(self):
        import jax

        import baselines
        import polyjax as pj

        s, d = self.s, self.curet
        nm = d.values.shape[0]
        key = jax.random.PRNGKey(s.seed)
        out = {}
        for name in s.nonlinear:
            f, first, best = timed(lambda: baselines.fit(name, d, n_starts=s.n_starts, key=key), s.repeats)
            out[name] = self._record(f.l2, first, best, nm, f, extra={"converged": int(np.asarray(f.success).sum())})
            self.step(f"CUReT {name}")
        for key_, order in (("zernike", 8), ("zernike2", 2)):
            f, first, best = timed(lambda: baselines.fit("zernike", d, order=order), s.repeats)
            out[key_] = self._record(f.l2, first, best, nm, f)
        self.step("CUReT Zernike")
        configs = poly_configs(s.degrees, CURET_POLY + FIG7_POLY)
        for var in VARIABLE_SETS:
            for p in (p for v, p in configs if v == var):
                m, first, best = timed(lambda: pj.fit_polynomial(d, variables=var, degree=p), s.repeats)
                out[poly_key(var, p)] = self._record(m.l2, first, best, nm, m,
                                                     extra={"n_params": int(np.asarray(m.n_params).ravel()[0])})
            self.step(f"CUReT poly {var}")
        self.curet_out = out

    def _record(self, l2, first, best, n_materials, fit, extra=None):
        l2 = np.asarray(l2, dtype=float)
        rec = {"l2": l2.tolist(), "mean_l2": float(np.mean(l2)), "seconds_batch": best,
               "seconds_per_material": best / n_materials, "compile_seconds": max(first - best, 0.0),
               "_fit": fit}
        rec.update(extra or {})
        return rec

    # -- MERL fits -------------------------------------------------------------------------------
    def merl_fits(self):
        import jax

        import baselines
        import polyjax as pj

        s, d, df = self.s, self.merl, self.merl_fit
        nm = d.values.shape[0]
        key = jax.random.PRNGKey(s.seed)
        out = {}
        for name in s.nonlinear:
            f, first, best = timed(lambda: baselines.fit(name, df, n_starts=s.n_starts, key=key), s.repeats)
            pred = f(d.u, d.v)
            l2 = pj.l2_error(d.values, pred, d.u, d.v, weights=d.weights, mask=d.mask)  # (m, 3) on the eval grid
            out[name] = self._record(l2, first, best, nm, f, extra={"l2_on_fit_subsample": np.asarray(f.l2).tolist()})
            self.step(f"MERL {name}")
        configs = poly_configs(s.degrees, MERL_POLY)
        for var in VARIABLE_SETS:
            for p in (p for v, p in configs if v == var):
                m, first, best = timed(lambda: pj.fit_polynomial(d, variables=var, degree=p), s.repeats)
                out[poly_key(var, p)] = self._record(m.l2, first, best, nm, m)
            self.step(f"MERL poly {var}")
        self.merl_out = out

    # -- tables ----------------------------------------------------------------------------------
    def tables(self):
        c, m = self.curet_out, self.merl_out
        ids = list(self.curet.ids)
        pos = [ids.index(i) for i in TABLE2_IDS if i in ids]
        t2 = {}
        for key, paper in PAPER_TABLE2.items():
            if key not in c:
                continue
            l2 = np.asarray(c[key]["l2"])[pos]
            t2[key] = {"ours": l2.tolist(), "paper": list(paper)}
        self.res["table2"] = {"samples": [self.curet.names[i] for i in pos], "ids": [ids[i] for i in pos], "rows": t2}
        t3 = {}
        names = list(self.s.merl_names)
        for key, paper in PAPER_TABLE3.items():
            if key not in m:
                continue
            l2 = np.asarray(m[key]["l2"]).mean(-1)  # mean over R, G, B
            pp = {n: paper[list(_table3_names()).index(n)] for n in names}
            t3[key] = {"ours_l2": l2.tolist(), "ours_l2_rgb": m[key]["l2"], "paper_l2": [pp[n][0] for n in names],
                       "paper_psnr": [pp[n][1] for n in names]}
        self.res["table3"] = {"materials": names, "rows": t3}
        t4 = {}
        for key, paper in PAPER_TABLE4.items():
            if key not in c:
                continue
            t4[key] = {"ours_s": c[key]["seconds_per_material"], "compile_s": c[key]["compile_seconds"], "paper_s": paper,
                       "speedup_vs_paper": paper / c[key]["seconds_per_material"]}
        t4["zernike"] = {"ours_s": c["zernike"]["seconds_per_material"], "compile_s": c["zernike"]["compile_seconds"],
                         "paper_s": None, "speedup_vs_paper": None}
        self.res["table4"] = {"n_materials": len(ids), "n_starts": self.s.n_starts, "rows": t4}
        # Fig. 6 counts: lowest L2 among the seven nonlinear models and the polynomial model
        nl = np.stack([np.asarray(c[n]["l2"]) for n in self.s.nonlinear])
        counts = {}
        for var, p in CURET_POLY:
            k = poly_key(var, p)
            counts[k] = {"ours": int(np.sum(np.asarray(c[k]["l2"]) < nl.min(0))), "of": len(ids),
                         "paper": PAPER_LOWEST_COUNTS[k], "paper_of": 52}
        self.res["lowest_counts"] = counts

    # -- figures ---------------------------------------------------------------------------------
    def figs_67(self):
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        c = self.curet_out
        names = list(self.curet.names)
        x = np.arange(len(names))
        fig6_keys = list(self.s.nonlinear) + [poly_key(v, p) for v, p in CURET_POLY]
        sort_by = "cook-torrance" if "cook-torrance" in c else self.s.nonlinear[0]
        order = np.argsort(np.asarray(c[sort_by]["l2"]))
        fig, ax = plt.subplots(figsize=(12, 5))
        for k in fig6_keys:
            style = "-o" if k.startswith("poly:") else "--."
            ax.plot(x, np.asarray(c[k]["l2"])[order], style, ms=3, lw=1, label=label(k))
        ax.set_xticks(x)
        ax.set_xticklabels([names[i] for i in order], rotation=90, fontsize=6)
        ax.set_ylabel("L2 (eq. 11)")
        ax.set_title(f"Fig. 6: L2 on {len(names)} isotropic CUReT samples, sorted by {label(sort_by)}")
        ax.legend(fontsize=7, ncol=2)
        fig.tight_layout()
        fig.savefig(self.out / "fig6_curet52.png", dpi=110)
        plt.close(fig)
        fig7_keys = [poly_key(*FIG7_POLY[0]), poly_key(*FIG7_POLY[1]), "zernike2", "zernike"]
        order = np.argsort(np.asarray(c[poly_key(*FIG7_POLY[1])]["l2"]))
        fig, ax = plt.subplots(figsize=(12, 5))
        for k in fig7_keys:
            npar = f" ({c[k]['n_params']} par.)" if "n_params" in c[k] else (" (55 par.)" if k == "zernike" else " (5 par.)")
            ax.plot(x, np.asarray(c[k]["l2"])[order], "-o", ms=3, lw=1, label=label(k) + npar)
        ax.set_xticks(x)
        ax.set_xticklabels([names[i] for i in order], rotation=90, fontsize=6)
        ax.set_ylabel("L2 (eq. 11)")
        ax.set_title("Fig. 7: linear models, sorted by Poly. (Lafortune, p = 8)")
        ax.legend(fontsize=8)
        fig.tight_layout()
        fig.savefig(self.out / "fig7_linear_models.png", dpi=110)
        plt.close(fig)
        self.res["figs"] = {"fig6": "fig6_curet52.png", "fig7": "fig7_linear_models.png", "fig6_sorted_by": sort_by}

    def renders(self):
        import polyjax as pj
        import polyjax.render as pr

        s = self.s
        size = s.size
        scene = pr.sphere_scene(size)
        c, m = self.curet_out, self.merl_out
        ids = list(self.curet.ids)
        pos = [ids.index(i) for i in TABLE2_IDS if i in ids]
        rows_keys = list(s.nonlinear) + ["zernike"] + [poly_key(v, p) for v, p in CURET_POLY]
        rows = [[self._brdf(c[k]["_fit"], k, j) for j in pos] for k in rows_keys]
        g = pr.render_grid(rows, scene)
        images = np.asarray(g.images, np.float32)
        ex = _exposure(images[rows_keys.index("zernike")], g.hit)
        big = pr.mosaic(images, pad=2, fill=0.0)
        pr.write_exr(self.out / "fig3_curet_spheres.exr", big)
        pr.write_png(self.out / "fig3_curet_spheres.png", big, exposure=ex)
        figs = {"fig3": {"rows": [label(k) for k in rows_keys], "cols": [self.curet.names[j] for j in pos],
                         "exposure_stops": ex, "files": ["fig3_curet_spheres.exr", "fig3_curet_spheres.png"]}}
        self.step("render Fig. 3")
        # Table 3 PSNR: measured (neural network) vs every model, one sphere per material
        t3_keys = list(s.nonlinear) + [poly_key(v, p) for v, p in MERL_POLY]
        names = list(s.merl_names)
        refs = [pj.data.load_nbrdf(n, root=self.root) for n in names]
        rows = [refs] + [[self._brdf(m[k]["_fit"], k, j) for j in range(len(names))] for k in t3_keys]
        g = pr.render_grid(rows, scene)
        images = np.asarray(g.images, np.float32)
        hit = np.asarray(g.hit)
        psnr = {k: [] for k in t3_keys}
        exps = []
        for j, n in enumerate(names):
            ex = _exposure(images[0, j], hit)
            exps.append(ex)
            stem = "fig5_blue_metallic_paint" if n == "blue-metallic-paint" else f"table3_{n.replace('-', '_')}"
            col = pr.mosaic([[images[0, j]] + list(images[1:, j])], pad=2, fill=0.0)
            pr.write_exr(self.out / f"{stem}.exr", col)
            scores = pr.comparison_figure(self.out / f"{stem}.png", images[0, j], list(images[1:, j]),
                                          [label(k) for k in t3_keys], reference_name=f"{n} (neural MERL)", exposure=ex,
                                          mask=hit)
            for k in t3_keys:
                psnr[k].append(scores[label(k)])
        figs["table3_psnr"] = {"exposure_stops": exps, "psnr": psnr, "tonemap": "clip, sRGB, peak 1, sphere pixels only"}
        for k in t3_keys:
            self.res["table3"]["rows"][k]["ours_psnr"] = psnr[k]
        self.step("render Table 3 / Fig. 5")
        # Fig. 8: reciprocity, orange-paint, Lafortune p = 5
        j = names.index("orange-paint") if "orange-paint" in names else 0
        b = self._brdf(m[poly_key("lafortune", 5)]["_fit"], poly_key("lafortune", 5), j)
        g = pr.render_grid([[refs[j], b, pr.SwapUV(b)]], scene)
        images = np.asarray(g.images, np.float32)[0]
        ex = _exposure(images[0], g.hit)
        pr.write_exr(self.out / "fig8_reciprocity.exr", pr.mosaic([list(images)], pad=2, fill=0.0))
        scores = pr.comparison_figure(self.out / "fig8_reciprocity.png", images[0], [images[1], images[2]],
                                      ["Poly. (Lafortune, p = 5)", "same, u and v swapped"],
                                      reference_name=f"{names[j]} (neural MERL)", exposure=ex, mask=np.asarray(g.hit))
        swap = float(np.max(np.abs(images[1] - images[2])))
        figs["fig8"] = {"material": names[j], "psnr": scores, "max_abs_pixel_difference_swapped": swap,
                        "max_pixel": float(images[1].max())}
        self.res["renders"] = figs
        self.step("render Fig. 8")

    @staticmethod
    def _brdf(fit, key, j):
        import polyjax as pj
        import polyjax.render as pr

        if isinstance(fit, pj.PolynomialBRDF):
            return pr.rgb_brdf(fit[j])
        return _BaselineBRDF(jnp.asarray(np.asarray(fit.params)[j]), fit.name)

    # -- references: scipy least_squares and a numpy lstsq loop ----------------------------------
    def references(self):
        s = self.s
        ref: dict = {}
        try:
            import scipy  # noqa: F401
        except ImportError:
            ref["scipy"] = {"skipped": "scipy is not installed (pip install 'polyjax[test]' or scipy) - no scipy reference"}
            print("NOTE: scipy is not installed: the scipy.optimize.least_squares reference is skipped")
        else:
            ref["scipy"] = self._scipy()
        self.step("scipy reference")
        ref["numpy"] = self._numpy()
        self.step("numpy reference")
        self.res["references"] = ref

    def _scipy(self):
        import jax

        import baselines

        s, d = self.s, self.curet
        nm = d.values.shape[0]
        idx = np.linspace(0, nm - 1, s.scipy_materials).round().astype(int) if s.scipy_materials < nm else np.arange(nm)
        key = jax.random.PRNGKey(s.seed)
        out = {"materials": [d.names[i] for i in idx], "n_starts": s.n_starts, "method": "lm (MINPACK)", "models": {}}
        for name in s.nonlinear:
            starts = baselines.initial_guesses(name, d, n_starts=s.n_starts, key=key)
            best, per = scipy_best_l2(name, d, starts, idx)
            ours = np.asarray(self.curet_out[name]["l2"])[idx]
            ours_t = self.curet_out[name]["seconds_per_material"]
            out["models"][name] = {
                "l2_scipy": best.tolist(), "l2_ours": ours.tolist(), "seconds_per_material": per,
                "speedup_ours_vs_scipy": per / ours_t,
                "ours_le_scipy_fraction": float(np.mean(ours <= best * (1 + 1e-3) + 1e-7)),
            }
        return out

    def _numpy(self):
        """Weighted least squares with ``numpy.linalg.lstsq``, one material (and channel) at a time, the design
        (PCA, monomials) built once per data set and configuration inside the timing."""
        s = self.s
        out = {}
        jobs = [("curet", self.curet, CURET_POLY, self.curet_out, np.arange(self.curet.values.shape[0])),
                ("merl", self.merl, MERL_POLY, self.merl_out, np.arange(min(s.numpy_merl_materials, len(s.merl_names))))]
        for ds, d, configs, ours, mats in jobs:
            u, v = np.asarray(d.u), np.asarray(d.v)
            vals = np.asarray(d.values)
            wts = np.ones(u.shape[0]) if d.weights is None else np.asarray(d.weights)
            out[ds] = {"materials": len(mats), "configs": {}}
            for var, p in configs:
                numpy_design(u[:64], v[:64], wts[:64], var, p)  # warm up the JAX explanatory variables
                t0 = time.perf_counter()
                a, keep, sw = numpy_design(u, v, wts, var, p)  # shared geometry: one design for every material
                l2 = [[numpy_lstsq_l2(a, keep, sw, y, wts) for y in vals[b].reshape(-1, vals.shape[-1])] for b in mats]
                per = (time.perf_counter() - t0) / len(mats)
                ref_l2 = np.asarray(ours[poly_key(var, p)]["l2"])[mats].reshape(len(mats), -1)
                out[ds]["configs"][poly_key(var, p)] = {
                    "seconds_per_material": per, "speedup_ours_vs_numpy": per / ours[poly_key(var, p)]["seconds_per_material"],
                    "max_rel_l2_difference": float(np.max(np.abs(np.asarray(l2) - ref_l2) / ref_l2)),
                }
        return out

    # -- accuracy vs time ------------------------------------------------------------------------
    def accuracy_vs_time(self):
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        fig, axes = plt.subplots(1, 2, figsize=(13, 5.5))
        result = {}
        md = []
        for ax, (ds, recs) in zip(axes, (("CUReT", self.curet_out), ("MERL (neural)", self.merl_out))):
            pts = [(k, r["seconds_per_material"], r["mean_l2"]) for k, r in recs.items() if np.isfinite(r["mean_l2"])]
            front = pareto_front([(t, e) for _, t, e in pts])
            for i, (k, t, e) in enumerate(pts):
                if k.startswith("poly:"):
                    var = k.split(":")[1]
                    mk = {"ashikhmin-shirley": "o", "lafortune": "s", "ward": "^"}[var]
                    ax.scatter(t, e, marker=mk, s=18, c="C0" if i in front else "0.6")
                    ax.annotate(k.split(":")[2], (t, e), fontsize=6, xytext=(2, 2), textcoords="offset points")
                else:
                    ax.scatter(t, e, marker="*", s=60, c="C3" if i in front else "C1")
                    ax.annotate(label(k), (t, e), fontsize=6, xytext=(3, -6), textcoords="offset points")
            fr = sorted((pts[i] for i in front), key=lambda q: q[1])
            ax.plot([q[1] for q in fr], [q[2] for q in fr], "-", c="C2", lw=1, label="Pareto front")
            for var, mk in (("ashikhmin-shirley", "o"), ("lafortune", "s"), ("ward", "^")):
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
            md.append(f"### {ds}\n\n" + _md_table(
                ["model", "time per material (s)", "mean L2"], [[label(k), f"{t:.3g}", f"{e:.5f}"] for k, t, e in fr]))
        fig.tight_layout()
        fig.savefig(self.out / "accuracy_vs_time.png", dpi=110)
        plt.close(fig)
        (self.out / "accuracy_vs_time.md").write_text("## Accuracy vs fit time: Pareto front\n\n" + "\n".join(md))
        self.res["accuracy_vs_time"] = result
        self.step("accuracy vs time")


def _table3_names():
    import polyjax as pj

    return pj.data.TABLE3_MATERIALS


def pareto_front(points) -> list[int]:
    """Indices of the points ``(time, error)`` not dominated by another (no other is as fast and more accurate)."""
    order = sorted(range(len(points)), key=lambda i: (points[i][0], points[i][1]))
    front, best = [], np.inf
    for i in order:
        if points[i][1] < best:
            front.append(i)
            best = points[i][1]
    return front


# ------------------------------------------------------------------------------------------------
# writing


def write_tables(res: dict, out: Path) -> str:
    """Markdown of Tables 1-4, the N-of-52 counts and the reference timings; returns the whole report."""
    parts = []
    t1 = res["table1"]
    rows = []
    for i, p in enumerate(t1["degrees"]):
        q, qp = t1["quarry_tile"][i], PAPER_TABLE1["Quarry Tile"][i]
        cy, cp = t1["cayman"]["luminance"]["mean"][i], PAPER_TABLE1["Cayman lacquer"][i]
        cr = t1["cayman"]["rgb"]["mean"][i]
        rows.append([str(p), str(t1["n_params_kp1"][i]), str(t1["n_params_paper_column"][i]), _fmt(q), _fmt(qp),
                     _fmt(q / qp, 2), _fmt(cy), _fmt(cr), _fmt(cp), _fmt(cy / cp, 2)])
    s1 = ("## Table 1: Lafortune-variable polynomial, L2 vs degree\n\n"
          "#Par: kp+1 = 2p+1 coefficients fitted (eq. 12); the paper's column counts 2p+5. Cayman: CIE Y luminance "
          f"({t1['cayman']['n_samples']} samples; RGB = mean of the R, G, B fits). Quarry tile: CUReT 25, RGB average.\n\n"
          + _md_table(["p", "#Par kp+1", "#Par paper", "Quarry ours", "Quarry paper", "ratio", "Cayman ours (Y)",
                       "Cayman ours (RGB)", "Cayman paper", "ratio (Y)"], rows)
          + f"\nCayman luminance, L2 of the zero model f = 0: {t1['cayman']['luminance_l2_of_zero_model']:.4f}\n")
    parts.append(s1)
    t2 = res["table2"]
    rows = []
    for k, r in t2["rows"].items():
        for n, a, b in zip(t2["samples"], r["ours"], r["paper"]):
            rows.append([label(k), n, _fmt(a), _fmt(b), _fmt(a / b, 2)])
    parts.append("## Table 2: L2 on five CUReT samples (RGB average)\n\n"
                 + _md_table(["model", "sample", "ours", "paper", "ratio"], rows))
    t3 = res["table3"]
    rows = []
    for k, r in t3["rows"].items():
        for j, n in enumerate(t3["materials"]):
            a, b = r["ours_l2"][j], r["paper_l2"][j]
            ps, pp = r.get("ours_psnr", [None] * len(t3["materials"]))[j], r["paper_psnr"][j]
            rows.append([label(k), n, _fmt(a), _fmt(b), _fmt(a / b, 2), _fmt(ps, 2), f"{pp:.2f}",
                         _fmt(None if ps is None else ps / pp, 2)])
    parts.append("## Table 3: L2 (mean over R, G, B) and PSNR (dB, sphere renderings vs the neural reference) "
                 "on MERL materials\n\n"
                 + _md_table(["model", "material", "L2 ours", "L2 paper", "ratio", "PSNR ours", "PSNR paper", "ratio"], rows))
    t4 = res["table4"]
    rows = [[label(k), f"{r['ours_s'] * 1e3:.3f}", f"{r['compile_s']:.2f}", "-" if r["paper_s"] is None else f"{r['paper_s']:.5f}",
             "-" if r["speedup_vs_paper"] is None else f"{r['speedup_vs_paper']:.0f}x"] for k, r in t4["rows"].items()]
    parts.append(f"## Table 4: fit time per material, {t4['n_materials']} isotropic CUReT samples, "
                 f"{t4['n_starts']} starts (nonlinear)\n\n"
                 + _md_table(["model", "ours (ms)", "compile (s)", "paper (s)", "paper / ours"], rows))
    rows = [[label(k), f"{r['ours']} of {r['of']}", f"{r['paper']} of {r['paper_of']}"] for k, r in res["lowest_counts"].items()]
    parts.append("## Fig. 6 counts: polynomial model has the lowest L2 (vs the nonlinear models)\n\n"
                 + _md_table(["model", "ours", "paper"], rows))
    ref = res.get("references", {})
    lines = []
    sc = ref.get("scipy", {})
    if "skipped" in sc:
        lines.append(f"- scipy: {sc['skipped']}")
    elif sc:
        lines.append(f"scipy.optimize.least_squares (method='lm'), same {sc['n_starts']} starts, on "
                     f"{len(sc['materials'])} CUReT materials:\n")
        lines.append(_md_table(
            ["model", "scipy s/material", "ours s/material", "ours faster by", "ours L2 <= scipy", "paper s", "paper / ours"],
            [[label(k), f"{r['seconds_per_material']:.3f}", f"{r['seconds_per_material'] / r['speedup_ours_vs_scipy']:.5f}",
              f"{r['speedup_ours_vs_scipy']:.0f}x", f"{r['ours_le_scipy_fraction'] * 100:.0f}%",
              f"{PAPER_TABLE4[k]:.5f}", f"{res['table4']['rows'][k]['speedup_vs_paper']:.0f}x"]
             for k, r in sc["models"].items()]))
    npy = ref.get("numpy", {})
    for ds, r in npy.items():
        lines.append(f"\nnumpy.linalg.lstsq loop, {ds} ({r['materials']} material(s)):\n")
        lines.append(_md_table(["model", "numpy s/material", "ours faster by", "max rel. L2 difference"],
                               [[label(k), f"{q['seconds_per_material']:.5f}", f"{q['speedup_ours_vs_numpy']:.1f}x",
                                 f"{q['max_rel_l2_difference']:.1e}"] for k, q in r["configs"].items()]))
    parts.append("## References timed in the same run\n\n" + "\n".join(lines))
    names = ["table1.md", "table2.md", "table3.md", "table4.md", "lowest_counts.md", "references.md"]
    for n, text in zip(names, parts):
        (out / n).write_text(text)
    front = (out / "accuracy_vs_time.md").read_text() if (out / "accuracy_vs_time.md").exists() else ""
    head = (f"# Reproduction of Ozturk et al. 2008\n\nRun: {res['run']['started']}, {res['run']['seconds']:.0f} s wall "
            f"({'quick' if res['settings']['quick'] else 'full'}); machine: {res['machine']['cpu_count']} CPUs, "
            f"load average at start {res['machine']['loadavg_start']}, at end {res['machine']['loadavg_end']}.\n\n")
    return head + "\n".join(parts) + "\n" + front


def _strip(obj):
    """JSON-ready copy without the fitted objects (keys starting with ``_``), non-finite numbers as None."""
    if isinstance(obj, dict):
        return {k: _strip(v) for k, v in obj.items() if not str(k).startswith("_")}
    if isinstance(obj, (list, tuple)):
        return [_strip(v) for v in obj]
    if isinstance(obj, (np.floating, float)):
        return _finite(obj)
    if isinstance(obj, np.integer):
        return int(obj)
    if isinstance(obj, np.ndarray):
        return _strip(obj.tolist())
    return obj


def _versions() -> dict:
    from importlib import metadata

    out = {"python": sys.version.split()[0]}
    for pkg in ("polyjax", "jax", "jaxlib", "numpy", "scipy", "equinox", "optimistix", "lineax", "matplotlib", "tqdm"):
        try:
            out[pkg] = metadata.version(pkg)
        except metadata.PackageNotFoundError:
            out[pkg] = None
    return out


def _machine() -> dict:
    import jax

    return {"platform": platform.platform(), "processor": platform.processor() or platform.machine(),
            "cpu_count": os.cpu_count(), "jax_devices": [str(d) for d in jax.devices()],
            "loadavg_start": [round(x, 2) for x in os.getloadavg()]}


# ------------------------------------------------------------------------------------------------
# entry point


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="polyjax reproduce", description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="results", help="results folder (created)")
    ap.add_argument("--quick", action="store_true", help="a few materials, 2 nonlinear models, few starts, tiny renders")
    ap.add_argument("--data-root", default=None, help="measured data folder (default: $POLYJAX_DATA)")
    return ap


def main(argv: list[str] | None = None) -> int:
    """Run the reproduction; returns the exit status (2 without a data root)."""
    import jax

    jax.config.update("jax_enable_x64", True)
    from tqdm import tqdm

    import polyjax as pj

    args = build_parser().parse_args(argv)
    if not pj.has_data_root(args.data_root):
        print(f"polyjax reproduce: error: the measured data root is missing: pass --data-root or set {pj.DATA_ENV} "
              "to the folder holding curet/, cornell/ and nbrdf_sztrajman2021/", file=sys.stderr)
        return 2
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    settings = Settings.make(args.quick)
    machine = _machine()
    t_start = time.perf_counter()
    started = time.strftime("%Y-%m-%d %H:%M:%S")
    n_steps = 1 + 2 * len(settings.nonlinear) + 1 + 2 * len(VARIABLE_SETS) + 3 + 2 + 1
    with tqdm(total=n_steps, unit="step", dynamic_ncols=True) as bar:
        run = Run(settings, out, args.data_root, bar)
        run.load()
        run.table1()
        run.step("Table 1")
        run.curet_fits()
        run.merl_fits()
        run.tables()
        run.figs_67()
        run.renders()
        run.references()
        run.accuracy_vs_time()
    machine["loadavg_end"] = [round(x, 2) for x in os.getloadavg()]
    run.res["machine"] = machine
    run.res["versions"] = _versions()
    run.res["run"] = {"started": started, "seconds": time.perf_counter() - t_start,
                      "note": "wall time on a shared machine: other processes may have run at the same time"}
    run.res["curet_fits"] = run.curet_out
    run.res["merl_fits"] = run.merl_out
    report = write_tables(run.res, out)
    (out / "report.md").write_text(report)
    (out / "results.json").write_text(json.dumps(_strip(run.res), indent=1))
    print(report)
    print(f"wrote {out}/ (report.md, results.json, tables, figures) in {run.res['run']['seconds']:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
