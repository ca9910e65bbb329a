"""The reproduction's report: labels, Markdown tables (Tables 1-4, Fig. 6 counts, references), the JSON record."""

from __future__ import annotations

import os
import platform
import sys
from importlib import metadata
from pathlib import Path

import jax
import numpy as np

from .constants import PAPER_TABLE1, PAPER_TABLE4

LABELS = {
    "ashikhmin-shirley": "Ashikhmin-Shirley", "blinn-phong": "Blinn-Phong", "cook-torrance": "Cook-Torrance",
    "lafortune": "Lafortune", "oren-nayar": "Oren-Nayar", "ward": "Ward", "ward-duer": "Ward-Duer",
    "zernike": "Zernike (order 8)", "zernike2": "Zernike (order 2)",
}


def label(key: str) -> str:
    """The paper's name of a model key (``poly:<variables>:<p>`` or a baseline name)."""
    if key.startswith("poly:"):
        _, var, p = key.split(":")
        return f"Poly. ({LABELS[var]}, p = {p})"
    return LABELS.get(key, key)


def _finite(x) -> float | None:
    x = float(x)
    return x if np.isfinite(x) else None


def _fmt(x, nd=4) -> str:
    if x is None or not np.isfinite(x):
        return "-"
    return f"{x:.{nd}f}"


def md_table(header: list[str], rows: list[list[str]]) -> str:
    """A Markdown table."""
    out = ["| " + " | ".join(header) + " |", "|" + "|".join(["---"] * len(header)) + "|"]
    out += ["| " + " | ".join(r) + " |" for r in rows]
    return "\n".join(out) + "\n"


def _table1(t1: dict) -> str:
    rows = []
    for i, p in enumerate(t1["degrees"]):
        q, qp = t1["quarry_tile"][i], PAPER_TABLE1["Quarry Tile"][i]
        cy, cp = t1["cayman"]["luminance"]["mean"][i], PAPER_TABLE1["Cayman lacquer"][i]
        cr = t1["cayman"]["rgb"]["mean"][i]
        rows.append([str(p), str(t1["n_params_kp1"][i]), str(t1["n_params_paper_column"][i]), _fmt(q), _fmt(qp),
                     _fmt(q / qp, 2), _fmt(cy), _fmt(cr), _fmt(cp), _fmt(cy / cp, 2)])
    return ("## Table 1: Lafortune-variable polynomial, L2 vs degree\n\n"
            "#Par: kp+1 = 2p+1 coefficients fitted (eq. 12); the paper's column counts 2p+5. Cayman: CIE Y luminance "
            f"({t1['cayman']['n_samples']} samples; RGB = mean of the R, G, B fits). Quarry tile: CUReT 25, RGB "
            "average.\n\n"
            + md_table(["p", "#Par kp+1", "#Par paper", "Quarry ours", "Quarry paper", "ratio", "Cayman ours (Y)",
                        "Cayman ours (RGB)", "Cayman paper", "ratio (Y)"], rows)
            + f"\nCayman luminance, L2 of the zero model f = 0: {t1['cayman']['luminance_l2_of_zero_model']:.4f}\n")


def _table2(t2: dict) -> str:
    rows = []
    for k, r in t2["rows"].items():
        for n, a, b in zip(t2["samples"], r["ours"], r["paper"]):
            rows.append([label(k), n, _fmt(a), _fmt(b), _fmt(a / b, 2)])
    return "## Table 2: L2 on five CUReT samples (RGB average)\n\n" + md_table(
        ["model", "sample", "ours", "paper", "ratio"], rows)


def _table3(t3: dict) -> str:
    rows = []
    for k, r in t3["rows"].items():
        for j, n in enumerate(t3["materials"]):
            a, b = r["ours_l2"][j], r["paper_l2"][j]
            ps, pp = r.get("ours_psnr", [None] * len(t3["materials"]))[j], r["paper_psnr"][j]
            rows.append([label(k), n, _fmt(a), _fmt(b), _fmt(a / b, 2), _fmt(ps, 2), f"{pp:.2f}",
                         _fmt(None if ps is None else ps / pp, 2)])
    return ("## Table 3: L2 (mean over R, G, B) and PSNR (dB, sphere renderings vs the neural reference) "
            "on MERL materials\n\n"
            + md_table(["model", "material", "L2 ours", "L2 paper", "ratio", "PSNR ours", "PSNR paper", "ratio"],
                       rows))


def _table4(t4: dict) -> str:
    rows = [[label(k), f"{r['ours_s'] * 1e3:.3f}", f"{r['compile_s']:.2f}",
             "-" if r["paper_s"] is None else f"{r['paper_s']:.5f}",
             "-" if r["speedup_vs_paper"] is None else f"{r['speedup_vs_paper']:.0f}x"] for k, r in t4["rows"].items()]
    return (f"## Table 4: fit time per material, {t4['n_materials']} isotropic CUReT samples, "
            f"{t4['n_starts']} starts (nonlinear)\n\n"
            + md_table(["model", "ours (ms)", "compile (s)", "paper (s)", "paper / ours"], rows))


def _references(ref: dict, table4: dict) -> str:
    lines = []
    sc = ref.get("scipy", {})
    if "skipped" in sc:
        lines.append(f"- scipy: {sc['skipped']}")
    elif sc:
        lines.append(f"scipy.optimize.least_squares (method='lm'), same {sc['n_starts']} starts, on "
                     f"{len(sc['materials'])} CUReT materials:\n")
        lines.append(md_table(
            ["model", "scipy s/material", "ours s/material", "ours faster by", "ours L2 <= scipy", "paper s",
             "paper / ours"],
            [[label(k), f"{r['seconds_per_material']:.3f}",
              f"{r['seconds_per_material'] / r['speedup_ours_vs_scipy']:.5f}", f"{r['speedup_ours_vs_scipy']:.0f}x",
              f"{r['ours_le_scipy_fraction'] * 100:.0f}%", f"{PAPER_TABLE4[k]:.5f}",
              f"{table4['rows'][k]['speedup_vs_paper']:.0f}x"] for k, r in sc["models"].items()]))
    for ds, r in ref.get("numpy", {}).items():
        lines.append(f"\nnumpy.linalg.lstsq loop, {ds} ({r['materials']} material(s)):\n")
        lines.append(md_table(["model", "numpy s/material", "ours faster by", "max rel. L2 difference"],
                              [[label(k), f"{q['seconds_per_material']:.5f}", f"{q['speedup_ours_vs_numpy']:.1f}x",
                                f"{q['max_rel_l2_difference']:.1e}"] for k, q in r["configs"].items()]))
    return "## References timed in the same run\n\n" + "\n".join(lines)


def write_tables(res: dict, out: Path) -> str:
    """Write ``table1.md`` .. ``table4.md``, ``lowest_counts.md``, ``references.md``; returns the whole report."""
    rows = [[label(k), f"{r['ours']} of {r['of']}", f"{r['paper']} of {r['paper_of']}"]
            for k, r in res["lowest_counts"].items()]
    parts = {
        "table1.md": _table1(res["table1"]), "table2.md": _table2(res["table2"]), "table3.md": _table3(res["table3"]),
        "table4.md": _table4(res["table4"]),
        "lowest_counts.md": "## Fig. 6 counts: polynomial model has the lowest L2 (vs the nonlinear models)\n\n"
        + md_table(["model", "ours", "paper"], rows),
        "references.md": _references(res.get("references", {}), res["table4"]),
    }
    for name, text in parts.items():
        (out / name).write_text(text)
    front = (out / "accuracy_vs_time.md").read_text() if (out / "accuracy_vs_time.md").exists() else ""
    head = (f"# Reproduction of Ozturk et al. 2008\n\nRun: {res['run']['started']}, {res['run']['seconds']:.0f} s "
            f"wall ({'quick' if res['settings']['quick'] else 'full'}); machine: {res['machine']['cpu_count']} CPUs, "
            f"load average at start {res['machine']['loadavg_start']}, at end {res['machine']['loadavg_end']}.\n\n")
    return head + "\n".join(parts.values()) + "\n" + front


def strip(obj):
    """JSON-ready copy without the fitted objects (keys starting with ``_``), non-finite numbers as None."""
    if isinstance(obj, dict):
        return {k: strip(v) for k, v in obj.items() if not str(k).startswith("_")}
    if isinstance(obj, (list, tuple)):
        return [strip(v) for v in obj]
    if isinstance(obj, (np.floating, float)):
        return _finite(obj)
    if isinstance(obj, np.integer):
        return int(obj)
    if isinstance(obj, np.ndarray):
        return strip(obj.tolist())
    return obj


def versions() -> dict:
    """Versions of Python and the packages the run used."""
    out = {"python": sys.version.split()[0]}
    for pkg in ("polyjax", "jax", "jaxlib", "numpy", "scipy", "equinox", "optimistix", "lineax", "matplotlib", "tqdm"):
        try:
            out[pkg] = metadata.version(pkg)
        except metadata.PackageNotFoundError:
            out[pkg] = None
    return out


def machine() -> dict:
    """The machine: platform, CPUs, JAX devices, load average now."""
    return {"platform": platform.platform(), "processor": platform.processor() or platform.machine(),
            "cpu_count": os.cpu_count(), "jax_devices": [str(d) for d in jax.devices()],
            "loadavg_start": [round(x, 2) for x in os.getloadavg()]}
