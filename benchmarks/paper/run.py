r"""The reproduction run: the paper's Tables 1-4 and Figs. 3, 5, 6, 7, 8, plus accuracy vs fit time.

Every number is computed in the run and written to the results folder (``--out``):

- ``table1.md`` .. ``table4.md``: ours | paper | ratio (paper values: :mod:`benchmarks.paper.constants`);
- ``fig3_curet_spheres``, ``fig5_blue_metallic_paint``, ``fig8_reciprocity``, ``table3_<material>``
  (``.exr`` linear, ``.png`` sRGB), ``fig6_curet52.png``, ``fig7_linear_models.png``;
- ``accuracy_vs_time.png`` / ``.md``: mean L2 against fit time per material of every model and
  polynomial degree ``p`` (three variable sets) with the Pareto front; scipy ``least_squares`` and a
  numpy ``lstsq`` loop on the same data, timed in the same run;
- ``results.json``: every number, the settings, software versions and machine; ``report.md``: all tables.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from dataclasses import asdict
from pathlib import Path

import jax
from tqdm import tqdm

import polyjax as pj
import polyjax.render as pr

from . import experiments as ex
from . import figures
from .constants import VARIABLE_SETS
from .report import machine, strip, versions, write_tables


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="python benchmarks/reproduce.py", description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="results", help="results folder (created; default ./results)")
    ap.add_argument("--quick", action="store_true",
                    help="a few materials, 2 nonlinear models, few starts, tiny renders")
    ap.add_argument("--data-root", default=None, help="measured data folder (default: $POLYJAX_DATA)")
    return ap


def run(s: ex.Settings, out: Path, root=None, step=lambda what: None) -> dict:
    """Every experiment, figure and render of one run; returns the results record (``step`` marks progress)."""
    res: dict = {"settings": asdict(s)}
    data, res["data"] = ex.load_data(s, root)
    curet, merl = data["curet"], data["merl"]
    res["table1"] = ex.table1(root)
    step("Table 1")
    c = ex.curet_fits(s, curet, step)
    m = ex.merl_fits(s, merl, data["merl_fit"], step)
    res.update(ex.tables(s, curet, c, m))
    res["figs"] = figures.figs_67(s, curet, c, out)
    step("Figs. 6 and 7")
    scene = pr.sphere_scene(s.size)
    renders = {"fig3": figures.fig3(s, curet, c, out, scene)}
    step("render Fig. 3")
    refs = [pj.data.load_nbrdf(n, root=root) for n in s.merl_names]
    renders["table3_psnr"] = figures.table3_psnr(s, m, refs, out, scene)
    for k, scores in renders["table3_psnr"]["psnr"].items():
        res["table3"]["rows"][k]["ours_psnr"] = scores
    step("render Table 3 / Fig. 5")
    renders["fig8"] = figures.fig8(s, m, refs, out, scene)
    res["renders"] = renders
    step("render Fig. 8")
    res["references"] = ex.references(s, curet, merl, c, m, step)
    res["accuracy_vs_time"] = figures.accuracy_vs_time(c, m, out)
    step("accuracy vs time")
    res["curet_fits"], res["merl_fits"] = c, m
    return res


def main(argv: list[str] | None = None) -> int:
    """Run the reproduction; returns the exit status (2 without a data root or a writable ``--out``)."""
    jax.config.update("jax_enable_x64", True)
    args = build_parser().parse_args(argv)
    if not pj.has_data_root(args.data_root):
        print(f"reproduce: error: the measured data root is missing: pass --data-root or set {pj.DATA_ENV} "
              "to the folder holding curet/, cornell/ and nbrdf_sztrajman2021/", file=sys.stderr)
        return 2
    out = Path(args.out)
    try:
        out.mkdir(parents=True, exist_ok=True)
        (out / ".write-test").write_text("")
        (out / ".write-test").unlink()
    except OSError as e:
        print(f"reproduce: error: --out {out}: cannot write there ({e.strerror})", file=sys.stderr)
        return 2
    settings = ex.Settings.make(args.quick)
    mach = machine()
    t_start = time.perf_counter()
    started = time.strftime("%Y-%m-%d %H:%M:%S")
    n_steps = 1 + 2 * len(settings.nonlinear) + 1 + 2 * len(VARIABLE_SETS) + 1 + 3 + 2 + 1
    seconds: dict = {}
    with tqdm(total=n_steps, unit="step", dynamic_ncols=True) as bar:
        last = [time.perf_counter()]

        def step(what: str):
            """The end of a step: its wall time (compilation included) goes to ``results.json``."""
            now = time.perf_counter()
            seconds[what] = round(now - last[0], 3)
            last[0] = now
            bar.set_description(what)
            bar.update(1)

        res = run(settings, out, args.data_root, step)
    res["step_seconds"] = seconds
    mach["loadavg_end"] = [round(x, 2) for x in os.getloadavg()]
    res["machine"] = mach
    res["versions"] = versions()
    res["run"] = {"started": started, "seconds": time.perf_counter() - t_start,
                  "note": "wall time on a shared machine: other processes may have run at the same time"}
    report = write_tables(res, out)
    (out / "report.md").write_text(report)
    (out / "results.json").write_text(json.dumps(strip(res), indent=1))
    print(report)
    print(f"wrote {out}/ (report.md, results.json, tables, figures) in {res['run']['seconds']:.0f} s")
    return 0
