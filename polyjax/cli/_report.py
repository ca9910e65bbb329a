"""``polyjax report`` (the default command): fit the polynomial models of the paper's Tables 1, 2 and 4 and report
them; ``--html`` also writes the report as a ``polyjax view`` page."""

from __future__ import annotations

import time

import numpy as np

import polyjax as pj

from .._config import configured_data_root
from ._progress import compile_notice, progress_line
from ._view import report_page


def add_parser(sub, common) -> None:
    """The ``report`` command's parser."""
    r = sub.add_parser("report", parents=[common],
                       help="fit the polynomial models of the paper's tables and report them (default)")
    r.add_argument("--html", default=None, metavar="PAGE",
                   help="also write the report with its fits as an interactive HTML page (polyjax view)")
    r.set_defaults(func=cmd_report)



def cmd_report(args) -> int:
    """The main job: fit the polynomial models of the paper's Tables 1, 2 and 4 and report them."""
    with compile_notice("the report's fits", getattr(args, "cache_in_use", None)), progress_line("the report"):
        if getattr(args, "html", None):
            return report_page(args, _report)
        return _report(args)


def _report(args) -> int:
    if configured_data_root(args.data_root) is None:
        data = pj.data.synthetic_default()
        print(f"NOTE: no measured data (neither --data-root nor {pj.DATA_ENV} given). Running on the {data.source}.")
        print("      Set POLYJAX_DATA to the data folder (curet/, cornell/, nbrdf_sztrajman2021/) "
              "for the real report.\n")
        for var in ("lafortune", "ward", "ashikhmin-shirley"):
            m = pj.fit_polynomial(data, variables=var, degree=list(range(1, 9)))
            print(f"{var:<18s} L2 for p = 1..8 (rows: {', '.join(data.names)})")
            for j, name in enumerate(data.names):
                print(f"  {name:<18s} " + " ".join(f"{x:.4f}" for x in np.asarray(m.l2)[:, j]))
        return 0
    root = args.data_root
    data = pj.data.load_curet(root, pj.data.ISOTROPIC_52)
    print(f"data: {data.source}, {len(data.names)} isotropic samples, root {pj.data_root(root)}\n")
    i25 = data.ids.index(25)
    print("Table 1 (Quarry Tile, Lafortune variables): L2")
    m = pj.fit_polynomial(data, variables="lafortune", degree=[1, 2, 3, 4, 5, 6])
    for p in range(6):
        print(f"  p={p + 1}  #par={2 * (p + 1) + 1:<3d} {float(np.asarray(m.l2)[p, i25]):.4f}")
    print("\nPolynomial models on the 52 isotropic CUReT samples (one batched call per variable set):")
    for var, p in (("ashikhmin-shirley", 5), ("lafortune", 7), ("ward", 7)):
        t0 = time.perf_counter()
        mm = pj.fit_polynomial(data, variables=var, degree=p)
        l2 = np.asarray(mm.l2)
        dt = time.perf_counter() - t0
        all_ok = bool(np.all(np.asarray(mm.ok)))
        print(f"  {var:<18s} p={p}: median L2 {np.median(l2):.4f}, max {l2.max():.4f}, all OK: {all_ok}"
              f"  ({dt * 1e3:.1f} ms for 52 fits incl. compilation)")
    print("\nComparison with the paper's tables: python benchmarks/reproduce.py (in the source repository)")
    return 0


