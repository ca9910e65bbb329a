"""The ``polyjax`` command line: ``report`` (the default), ``fit``, ``render``, ``reproduce``."""

from __future__ import annotations

import argparse
import json
import sys
import time


def _x64() -> None:
    import jax

    jax.config.update("jax_enable_x64", True)


#: The paper's Table 1, L2 of the Lafortune-variable polynomial for p = 1..6.
PAPER_TABLE1 = {
    "Quarry Tile": (0.0324, 0.0205, 0.0142, 0.0116, 0.0106, 0.0093),
    "Cayman lacquer": (2.1983, 2.1981, 2.1981, 2.1979, 2.1972, 2.1953),
}


def _load_dataset(args):
    """Measurements from --dataset / --sample, or the synthetic default without a data root."""
    import polyjax as pj

    if args.dataset:
        return pj.data.load(args.dataset, root=args.data_root), False
    if pj.has_data_root(args.data_root):
        return pj.data.load_curet(args.data_root, [args.sample]), False
    return pj.data.synthetic_default(), True


def cmd_fit(args) -> int:
    import numpy as np

    import polyjax as pj

    data, synthetic = _load_dataset(args)
    t0 = time.perf_counter()
    model = pj.fit_polynomial(
        data, variables=args.variables, degree=args.degree, basis=args.basis, interactions=args.interactions,
        cutoff_deg=args.cutoff,
    )
    l2 = np.asarray(model.l2)
    elapsed = time.perf_counter() - t0
    beta = model.paper_coefficients() if not args.interactions else np.asarray(model.coefficients)
    if args.save:
        pj.save_model(args.save, model)
    out = {
        "source": data.source,
        "synthetic": synthetic,
        "names": list(data.names),
        "channels": list(data.channels),
        "variables": model.variables,
        "degree": args.degree,
        "n_params": int(np.asarray(model.n_params).ravel()[0]),
        "l2": l2.tolist(),
        "rank": np.asarray(model.rank).tolist(),
        "condition": np.asarray(model.condition).tolist(),
        "status": [pj.FitStatus(int(s)).name for s in np.asarray(model.status).ravel()],
        "coefficients": beta.tolist(),
        "coefficient_form": "paper eq. (3): beta_0, then Z_1..Z_k, Z_1^2..Z_k^2, ..." if not args.interactions else "basis",
        "seconds": elapsed,
    }
    if args.json:
        print(json.dumps(out))
        return 0
    if synthetic:
        print(f"NOTE: no data root ({pj.DATA_ENV} unset): using the {data.source}")
    print(f"data: {data.source}")
    print(f"model: polynomial, variables={model.variables}, p={args.degree}, {out['n_params']} parameters, basis={args.basis}")
    names = data.names or ("",) * max(1, l2.size)
    flat_beta = beta.reshape(-1, beta.shape[-1])
    for i, (name, e) in enumerate(zip(names, l2.ravel())):
        print(f"  {name:<22s} L2 = {e:.5f}   cond = {np.asarray(model.condition).ravel()[i]:.3g}   {out['status'][i]}")
        print("    beta = " + " ".join(f"{b:+.5g}" for b in flat_beta[i]))
    print(f"fit time (including compilation): {elapsed:.3f} s")
    return 0


def cmd_report(args) -> int:
    """The main job: fit the polynomial model and report it beside the paper."""
    import numpy as np

    import polyjax as pj

    if not pj.has_data_root(args.data_root):
        data = pj.data.synthetic_default()
        print(f"NOTE: no measured data ({pj.DATA_ENV} unset or missing). Running on the {data.source}.")
        print("      Set POLYJAX_DATA to the data folder (curet/, cornell/, nbrdf_sztrajman2021/) for the real report.\n")
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
    print("Table 1 (Quarry Tile, Lafortune variables): L2 ours | paper")
    m = pj.fit_polynomial(data, variables="lafortune", degree=[1, 2, 3, 4, 5, 6])
    for p in range(6):
        ours = float(np.asarray(m.l2)[p, i25])
        paper = PAPER_TABLE1["Quarry Tile"][p]
        print(f"  p={p + 1}  #par={2 * (p + 1) + 1:<3d} {ours:.4f} | {paper:.4f}   ratio {ours / paper:.2f}")
    print("\nPolynomial models on the 52 isotropic CUReT samples (one batched call per variable set):")
    for var, p in (("ashikhmin-shirley", 5), ("lafortune", 7), ("ward", 7)):
        t0 = time.perf_counter()
        mm = pj.fit_polynomial(data, variables=var, degree=p)
        l2 = np.asarray(mm.l2)
        dt = time.perf_counter() - t0
        print(f"  {var:<18s} p={p}: median L2 {np.median(l2):.4f}, max {l2.max():.4f}, all OK: {bool(np.all(np.asarray(mm.ok)))}"
              f"  ({dt * 1e3:.1f} ms for 52 fits incl. compilation)")
    print("\nFull comparison with the paper's tables: polyjax reproduce")
    return 0


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="polyjax", description="Fit polynomial (and baseline) BRDF models to measured data.")
    p.add_argument("--data-root", default=None, help="measured data folder (default: $POLYJAX_DATA)")
    common = argparse.ArgumentParser(add_help=False)
    common.add_argument("--data-root", default=argparse.SUPPRESS, help="measured data folder (default: $POLYJAX_DATA)")
    sub = p.add_subparsers(dest="command")

    r = sub.add_parser("report", parents=[common], help="fit the polynomial model and report it beside the paper (default)")
    r.set_defaults(func=cmd_report)

    f = sub.add_parser("fit", parents=[common], help="fit the polynomial model to one dataset and print L2 and coefficients")
    f.add_argument("--sample", default="25", help="CUReT sample number or name (default 25, Quarry Tile)")
    f.add_argument("--dataset", default=None, help="dataset spec instead of --sample, e.g. curet:1,25 or merl-nbrdf:green-latex")
    f.add_argument("--variables", default="lafortune", help="ward | ashikhmin-shirley | lafortune | lafortune-anisotropic")
    f.add_argument("--degree", type=int, default=7)
    f.add_argument("--basis", default="legendre", choices=["legendre", "monomial"])
    f.add_argument("--interactions", action="store_true", help="full response surface of equation (2)")
    f.add_argument("--cutoff", type=float, default=80.0, help="grazing cutoff in degrees")
    f.add_argument("--save", default=None, help="write the fitted model (.npz or .json)")
    f.add_argument("--json", action="store_true", help="machine-readable output")
    f.set_defaults(func=cmd_fit)

    try:
        from .render._cli import add_render_parser, run_render
    except ImportError:
        pass
    else:
        rp = add_render_parser(sub, parents=[common])
        rp.set_defaults(func=run_render)

    from .export._cli import add_export_parser, run_export

    add_export_parser(sub, parents=[common]).set_defaults(func=run_export)

    rep = sub.add_parser("reproduce", parents=[common], help="reproduce the paper's Tables 1-4 and Figs. 3, 5-8 (see benchmarks/reproduce.py)")
    rep.add_argument("--quick", action="store_true")
    rep.add_argument("--out", default="results")
    rep.set_defaults(func=cmd_reproduce)
    return p


def cmd_reproduce(args) -> int:
    from ._reproduce import main as reproduce_main

    argv = ["--out", args.out] + (["--quick"] if args.quick else [])
    if args.data_root:
        argv += ["--data-root", args.data_root]
    return reproduce_main(argv)


def main(argv: list[str] | None = None) -> int:
    _x64()
    from ._errors import PolyjaxError

    parser = build_parser()
    args = parser.parse_args(argv)
    if args.command is None:
        args.func = cmd_report
    try:
        return int(args.func(args) or 0)
    except PolyjaxError as e:
        print(f"polyjax: error: {e}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
