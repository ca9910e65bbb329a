"""The ``polyjax`` command line: ``report`` (the default), ``fit``, ``render``, ``fit-images``.

The paper's reproduction is a script of the repository, not a command: ``python benchmarks/reproduce.py``.
"""

from __future__ import annotations

import argparse
import sys
import time


def _x64() -> None:
    import jax

    jax.config.update("jax_enable_x64", True)


def _load_dataset(args):
    """Measurements from --dataset / --sample, or the synthetic default when no data root is configured at all.

    A data root that is given (``--data-root`` or ``$POLYJAX_DATA``) but does not exist is an error.
    """
    import polyjax as pj

    from ._config import configured_data_root

    if args.dataset:
        return pj.data.load(args.dataset, root=args.data_root), False
    if configured_data_root(args.data_root) is not None:
        return pj.data.load_curet(args.data_root, [args.sample]), False
    return pj.data.synthetic_default(), True


def _parse_degrees(text, flag: str = "--degree") -> list[int]:
    """``"7"`` or ``"2,3,5"`` -> a list of non-negative integers; InputError naming ``flag`` otherwise."""
    from ._errors import InputError

    try:
        degrees = [int(d) for d in str(text).split(",") if d.strip()]
    except ValueError:
        degrees = []
    if not degrees or min(degrees) < 0:
        raise InputError(f"{flag}: expected a degree or comma-separated degrees (e.g. 5 or 2,3,5), found {text!r}")
    return degrees


def _lane_labels(data, lead: list[str] | None = None) -> list[str]:
    """One label per fitted lane, in C order over (leading labels, data batch axes): e.g. ``"p=2 alpha R"``.

    A material axis is labelled by ``data.names``, a channel axis by ``data.channels``; data without a material
    axis that names its one material (a single file) gets that name in front.
    """
    import itertools

    per_axis = [lead] if lead else []
    for i, size in enumerate(data.batch_shape):
        axis = data.axes[i] if i < len(data.axes) else ""
        if axis == "material" and len(data.names) == size:
            per_axis.append(list(data.names))
        elif axis == "channel" and len(data.channels) == size:
            per_axis.append(list(data.channels))
        else:
            per_axis.append([f"{axis or 'lane'} {j}" for j in range(size)])
    if "material" not in data.axes and len(data.names) == 1:
        per_axis.insert(1 if lead else 0, list(data.names))
    return [" ".join(parts) for parts in itertools.product(*per_axis)] or [""]


def samples_used(data, cutoff) -> int:
    """The fewest samples any lane of ``data`` keeps: inside the grazing cutoff (the rule of
    :func:`polyjax.cutoff_mask`), valid in its mask, with a positive weight (numpy on the host: nothing compiled)."""
    import numpy as np

    u, v = np.asarray(data.u), np.asarray(data.v)
    cu = u[..., 2] / np.maximum(np.linalg.norm(u, axis=-1), 1e-300)
    cv = v[..., 2] / np.maximum(np.linalg.norm(v, axis=-1), 1e-300)
    keep = (cu > 0) & (cv > 0)
    if cutoff is not None:  # the rule of pj.cutoff_mask, tolerance included
        c = np.cos(np.radians(float(cutoff))) - 1e-9
        keep = keep & (cu >= c) & (cv >= c)
    if data.mask is not None:
        keep = keep & np.asarray(data.mask)
    if data.weights is not None:
        keep = keep & (np.asarray(data.weights) > 0)
    keep = keep.reshape(-1, keep.shape[-1])
    return int(keep.sum(axis=-1).min())


def check_degrees_fit(data, variables, degrees, interactions, cutoff, flag: str) -> None:
    """Refuse, before any work, a degree whose polynomial has more parameters than the samples a fit uses (an
    interpolation, not a model: the command line never asks for one).

    Raises:
        InputError: naming ``flag``, the parameters and the samples used.
    """
    from ._basis import n_terms
    from ._errors import InputError
    from ._variables import get_variables

    vs = get_variables(variables)
    n = samples_used(data, cutoff)
    for p in degrees:
        m = n_terms(vs.k, int(p), bool(interactions))
        if m > n:
            ok = [q for q in range(int(p), -1, -1) if n_terms(vs.k, q, bool(interactions)) <= n]
            hint = f"; degree {ok[0]} or lower fits" if ok else ""
            raise InputError(f"{flag} {p}: expected at most as many parameters as the {n} samples used (inside "
                             f"the {cutoff} degree cutoff), found {m} parameters ({vs.name} variables{hint})")


#: a fit whose L2 is above this fraction of the L2 of f = 0 is reported as barely better than no model
ZERO_MODEL_RATIO = 0.95


def cmd_fit(args) -> int:
    """Run ``polyjax fit``: fit the model of ``--model`` to the dataset, optionally save it, and report every lane's
    L2, status and coefficients (text, or one JSON object with ``--json``); returns the exit status."""

    import polyjax as pj

    from ._kinds import fitter_for
    from ._outputs import check_model_file, strict_json

    degrees = _parse_degrees(args.degree)
    degree = degrees[0] if len(degrees) == 1 else degrees
    polynomial = args.model.strip().lower() == "polynomial"
    kind, model_name = (None, "polynomial") if polynomial else fitter_for(args.model)
    if args.save:
        check_model_file(args.save, "--save")
    data, synthetic = _load_dataset(args)
    if polynomial:
        check_degrees_fit(data, args.variables, degrees, args.interactions, args.cutoff, "--degree")
    model, l2, zero, elapsed = _run_fit(args, data, kind, model_name, degree)
    out, beta = _fit_record(args, data, synthetic, model, model_name, degrees, degree, l2, zero, elapsed)
    if args.save:
        out["saved"] = str(pj.save_model(args.save, model, metadata={"fit_seconds": elapsed, "fit_command": "fit"}))
    if args.json:
        print(strict_json(out))
        return 0
    if synthetic:
        print(f"NOTE: no data root (neither --data-root nor {pj.DATA_ENV} given): using the {data.source}")
    _print_fit(args, out, model, beta)
    return 0


def _run_fit(args, data, kind, model_name, degree):
    """The fit of ``polyjax fit`` (``kind`` None: the polynomial) -> ``(model, l2 array, zero-model L2 or None,
    seconds)``. A polynomial fit runs from the executable saved beside the cache when there is one
    (``polyjax/_aot.py``, which also returns the L2 of ``f = 0``), else through :func:`polyjax.fit_polynomial`."""
    import numpy as np

    import polyjax as pj

    from ._aot import fit_saved
    from ._cache import compile_notice
    from ._progress import progress_line

    t0 = time.perf_counter()
    cache = getattr(args, "cache_in_use", None)
    zero = None
    with compile_notice("the fit", cache), progress_line(f"fitting {model_name}"):
        if kind is None:
            options = dict(variables=args.variables, degree=degree, basis=args.basis, interactions=args.interactions,
                           cutoff_deg=args.cutoff)
            link = getattr(args, "link", "identity")
            saved = fit_saved(data, cache, **options) if link == "identity" else None
            options.update({} if link == "identity" else dict(link=link))
            model, zero = saved if saved is not None else (pj.fit_polynomial(data, **options), None)
        else:
            model = kind.fit(model_name, data, cutoff_deg=args.cutoff)
        l2 = np.asarray(model.l2)
    return model, l2, zero, time.perf_counter() - t0


def _fit_record(args, data, synthetic, model, model_name, degrees, degree, l2, zero, elapsed):
    """The JSON record of ``polyjax fit`` and the coefficients (or parameters) as one array."""
    import numpy as np

    from ._kinds import kind_of

    polynomial = model_name == "polynomial"
    if polynomial:
        beta = model.paper_coefficients() if not args.interactions else np.asarray(model.coefficients)
        form = "paper eq. (3): beta_0, then Z_1..Z_k, Z_1^2..Z_k^2, ..." if not args.interactions else "basis"
        n_par = np.asarray(model.n_params)
        n_params = [int(n_par[i].ravel()[0]) for i in range(len(degrees))] if isinstance(degree, list) \
            else int(n_par.ravel()[0])
    else:
        beta = np.asarray(model.params)
        form = "parameters: " + ", ".join(model.param_names)
        n_params = int(beta.shape[-1])
    status_names = kind_of(model).status_names
    status = [status_names[int(c)] if 0 <= int(c) < len(status_names) else str(int(c))
              for c in np.asarray(model.status).ravel()]
    labels = _lane_labels(data, [f"p={p}" for p in degrees] if isinstance(degree, list) else None)
    zero, warnings_ = _zero_model_check(data, l2, labels, args.cutoff, zero)
    if polynomial:
        warnings_ += _condition_warning(np.asarray(model.condition), np.asarray(model.status), labels)
    out = {
        "source": data.source,
        "synthetic": synthetic,
        "model": model_name,
        "names": list(data.names),
        "channels": list(data.channels),
        "labels": labels,
        "variables": model.variables if polynomial else None,
        "degree": degree if polynomial else None,
        "n_params": n_params,
        "l2": l2.tolist(),
        "l2_zero_model": zero.tolist(),
        "status": status,
        "coefficients": beta.tolist(),
        "coefficient_form": form,
        "seconds": elapsed,
        "warnings": warnings_,
    }
    if polynomial and getattr(model, "link", "identity") != "identity":
        out["link"] = model.link
    if polynomial:
        out["rank"] = np.asarray(model.rank).tolist()
        out["condition"] = np.asarray(model.condition).tolist()
    return out, beta


#: a full-rank fit whose weighted design has a condition number above this is reported as ill-conditioned
ILL_CONDITIONED = 1e7


def _condition_warning(cond, status, labels) -> list[str]:
    """A warning naming the full-rank lanes whose condition number exceeds :data:`ILL_CONDITIONED`: the samples
    barely determine that many parameters (a property of the samples, the same in either basis)."""
    import numpy as np

    high = (status.ravel() == 0) & np.isfinite(cond.ravel()) & (cond.ravel() > ILL_CONDITIONED)
    if not high.any():
        return []
    lanes = [f"{labels[i]} ({c:.3g})" for i, (c, h) in enumerate(zip(cond.ravel(), high)) if h]
    return [f"{len(lanes)} fit(s) ill-conditioned (condition number above {ILL_CONDITIONED:g}): " + "; ".join(lanes)
            + ". The samples barely determine this many parameters (in either basis: the same column space); "
            "coefficients are unreliable though the L2 is fine. Try a lower degree or no --interactions."]


def _zero_model_check(data, l2, labels, cutoff, zero=None):
    """The L2 of ``f = 0`` per lane (the shape of ``l2``; computed unless given) and a warning naming the lanes
    whose fit barely beats it (L2 above :data:`ZERO_MODEL_RATIO` of it), or no warning."""
    import numpy as np

    import polyjax as pj

    if zero is None:
        zero = pj.l2_error(data.values, 0.0, data.u, data.v, weights=data.weights, cutoff_deg=cutoff, mask=data.mask)
    zero = np.asarray(zero)
    zero = np.broadcast_to(zero, l2.shape)
    barely = (zero > 0) & np.isfinite(l2) & (l2 > ZERO_MODEL_RATIO * zero)
    warnings_ = []
    if barely.any():
        lanes = [f"{labels[i]} ({e:.4g} vs {z:.4g})" for i, (e, z, b) in
                 enumerate(zip(l2.ravel(), zero.ravel(), barely.ravel())) if b]
        warnings_.append(
            f"{len(lanes)} fit(s) barely beat the zero model f = 0 (L2 above {ZERO_MODEL_RATIO:g} of its L2): "
            + "; ".join(lanes)
            + ". The model cannot follow this data (e.g. a narrow peak); try another model or degree."
        )
    return zero, warnings_


def _print_fit(args, out: dict, model, beta) -> None:
    """The text report of ``polyjax fit`` from its JSON record ``out``."""
    import numpy as np

    polynomial = out["model"] == "polynomial"
    n_params, status = out["n_params"], out["status"]
    print(f"data: {out['source']}")
    if polynomial:
        counts = (f"p={args.degree} ({', '.join(map(str, n_params))} parameters)" if isinstance(n_params, list)
                  else f"p={args.degree}, {n_params} parameters")
        print(f"model: polynomial, variables={model.variables}, {counts}, "
              f"basis={args.basis}" + (f", link={out['link']}" if "link" in out else ""))
    else:
        print(f"model: {out['model']}, {n_params} parameters ({', '.join(model.param_names)})")
    flat_beta = beta.reshape(-1, beta.shape[-1])
    cond = np.asarray(model.condition).ravel() if polynomial else None
    for i, (label, e) in enumerate(zip(out["labels"], np.asarray(out["l2"]).ravel())):
        extra = f"   cond = {cond[i]:.3g}" if polynomial else ""
        print(f"  {label:<22s} L2 = {e:.5f}{extra}   {status[i]}")
        print(("    beta = " if polynomial else "    params = ") + " ".join(f"{b:+.5g}" for b in flat_beta[i]))
    for w in out["warnings"]:
        print(f"WARNING: {w}")
    print(f"fit time (including compilation): {out['seconds']:.3f} s")
    if out.get("saved"):
        print(f"model written to {out['saved']}")


def cmd_report(args) -> int:
    """The main job: fit the polynomial models of the paper's Tables 1, 2 and 4 and report them."""
    from ._cache import compile_notice
    from ._progress import progress_line

    with compile_notice("the report's fits", getattr(args, "cache_in_use", None)), progress_line("the report"):
        if getattr(args, "html", None):
            from .view._cli import report_page

            return report_page(args, _report)
        return _report(args)


def _report(args) -> int:
    import numpy as np

    import polyjax as pj

    from ._config import configured_data_root

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


def cmd_cache(args) -> int:
    """``polyjax cache info|clear``: what the cache folder holds (files, size, cap), or empty it."""
    from pathlib import Path

    from ._cache import default_cache_dir
    from ._cache_admin import MAX_ENV, cache_cap_bytes, cache_usage, clear_cache

    folder = default_cache_dir() if args.cache_dir is None else Path(args.cache_dir).expanduser()
    if args.action == "clear":
        n, size = clear_cache(folder)
        print(f"removed {n} file(s), {size / 2**20:.1f} MiB, from {folder}")
        return 0
    use, cap = cache_usage(folder), cache_cap_bytes()
    print(f"cache folder: {folder}{'' if folder.is_dir() else ' (not created yet)'}")
    print(f"  {use['files']} file(s), {use['bytes'] / 2**20:.1f} MiB; cap "
          + (f"{cap / 2**20:.0f} MiB" if cap else "none") + f" (${MAX_ENV}; least recently used files go first)")
    for part, (n, size) in sorted(use["parts"].items()):
        what = "JAX's compiled programs" if part == "." else part
        print(f"  {what}: {n} file(s), {size / 2**20:.1f} MiB")
    return 0


#: the built-in variable sets (pj.variable_sets() without importing JAX to print --help)
BUILTIN_VARIABLES = ("lafortune", "lafortune-anisotropic", "ward", "ashikhmin-shirley", "rusinkiewicz",
                     "rusinkiewicz-phid")

#: commands defined in this file: parsing them needs none of the other commands' modules (render, export, svbrdf)
_CORE_COMMANDS = ("fit", "report", "cache")


def _command_of(argv: list[str]) -> str | None:
    """The command named in ``argv`` (the first positional argument after the global options), if any."""
    i = 0
    while i < len(argv):
        a = argv[i]
        if a in ("--data-root", "--cache-dir"):
            i += 2
            continue
        if a.startswith("-"):
            i += 1
            continue
        return a
    return None


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The parser of every command, or, for ``command`` in :data:`_CORE_COMMANDS`, of the core commands only (the
    other commands' modules are then not imported: a shorter start for ``polyjax fit``)."""
    p = argparse.ArgumentParser(prog="polyjax",
                                description="Fit polynomial (and baseline) BRDF models to measured data.")
    root_help = ("measured data folder holding curet/, cornell/, nbrdf_sztrajman2021/ (default: $POLYJAX_DATA); "
                 "a folder given that does not exist is an error")
    cache_help = ("folder of JAX's persistent compilation cache, which lets later runs skip compiling (default: "
                  "$POLYJAX_CACHE, else $XDG_CACHE_HOME/polyjax/jax or ~/.cache/polyjax/jax)")
    no_cache_help = "do not read or write the compilation cache (also: POLYJAX_CACHE=off)"
    p.add_argument("--data-root", default=None, help=root_help)
    p.add_argument("--cache-dir", default=None, help=cache_help)
    p.add_argument("--no-cache", action="store_true", default=False, help=no_cache_help)
    common = argparse.ArgumentParser(add_help=False)
    common.add_argument("--data-root", default=argparse.SUPPRESS, help=root_help)
    common.add_argument("--cache-dir", default=argparse.SUPPRESS, help=cache_help)
    common.add_argument("--no-cache", action="store_true", default=argparse.SUPPRESS, help=no_cache_help)
    sub = p.add_subparsers(dest="command")

    r = sub.add_parser("report", parents=[common],
                       help="fit the polynomial models of the paper's tables and report them (default)")
    r.add_argument("--html", default=None, metavar="PAGE",
                   help="also write the report with its fits as an interactive HTML page (polyjax view)")
    r.set_defaults(func=cmd_report)

    f = sub.add_parser("fit", parents=[common], help="fit a model to one dataset and print L2 and coefficients",
                       description="Fit the polynomial model (or a baseline model, --model) to a dataset; one row per "
                       "fitted lane (degree x material x channel).")
    f.add_argument("--sample", default="25", help="CUReT sample number or name (default 25, Quarry Tile)")
    f.add_argument("--dataset", default=None,
                   help="dataset spec instead of --sample, e.g. curet:1,25, merl-nbrdf:green-latex, cornell:cayman, "
                   "merl:<file.binary>, nbrdf:<zip or folder>:<name>, rgl:<file.bsdf>")
    f.add_argument("--model", default="polynomial",
                   help="polynomial (default) or a baseline model, e.g. cook-torrance, ward, lafortune (any name of "
                   "baselines.MODELS); --variables, --degree, --basis, --interactions apply to the polynomial only")
    f.add_argument("--variables", default="lafortune",
                   help="explanatory variable set: " + " | ".join(BUILTIN_VARIABLES) + " (default lafortune)")
    f.add_argument("--link", default="identity", choices=["identity", "log"],
                   help="identity (default: the closed-form fit of equation (3)) or log: f = exp(P) - eps, fitted by "
                   "a few Gauss-Newton solves (pj.fit_polynomial(..., link='log'))")
    f.add_argument("--degree", "--degrees", dest="degree", default="7",
                   help="polynomial degree p, or comma-separated degrees fitted in one batch (e.g. 2,3,5); default 7")
    f.add_argument("--basis", default="legendre", choices=["legendre", "monomial"],
                   help="basis of the solve: scaled Legendre (default, well conditioned) or the paper's monomials")
    f.add_argument("--interactions", action="store_true", help="full response surface of equation (2)")
    f.add_argument("--cutoff", type=float, default=80.0, help="grazing cutoff in degrees (default 80)")
    f.add_argument("--save", default=None, help="write the fitted model (.npz or .json; format in README)")
    f.add_argument("--json", action="store_true", help="machine-readable output")
    f.set_defaults(func=cmd_fit)

    c = sub.add_parser("cache", parents=[common], help="what the compilation cache folder holds, or empty it",
                       description="info: the cache folder's files and size, and its cap ($POLYJAX_CACHE_MAX_MB, "
                       "default 2048; after each run the least recently used files are removed beyond it). clear: "
                       "remove every file in it (later runs compile again).")
    c.add_argument("action", choices=["info", "clear"], help="info or clear")
    c.set_defaults(func=cmd_cache)
    if command in _CORE_COMMANDS:
        return p

    _add_other_commands(sub, common)
    return p


def _add_other_commands(sub, common) -> None:
    """The commands beyond the core ones (render, fit-images, fit-photos, relight, export, svbrdf, view), each from
    its own module, imported here so that ``polyjax fit`` does not load them."""
    try:
        from .render._cli import add_render_parser, run_render
    except ImportError:
        pass
    else:
        rp = add_render_parser(sub, parents=[common])
        rp.set_defaults(func=run_render)
        from .render._fit_cli import add_fit_images_parser

        add_fit_images_parser(sub, parents=[common])
        from .render._photo_cli import add_photo_parsers

        add_photo_parsers(sub, parents=[common])

    from .export._cli import add_export_parser, run_export

    add_export_parser(sub, parents=[common]).set_defaults(func=run_export)
    from .svbrdf._cli import add_svbrdf_parser

    add_svbrdf_parser(sub, parents=[common])
    from .view._cli import add_view_parser

    add_view_parser(sub, parents=[common])


def _compilation_cache(args):
    """Turn on the persistent compilation cache unless ``--no-cache`` or ``POLYJAX_CACHE=off``; its folder or None."""
    from ._cache import cache_disabled_by_env, enable_compilation_cache

    if args.no_cache or (args.cache_dir is None and cache_disabled_by_env()):
        return None
    return enable_compilation_cache(args.cache_dir)


def main(argv: list[str] | None = None) -> int:
    _x64()
    from ._errors import PolyjaxError

    argv = sys.argv[1:] if argv is None else list(argv)
    parser = build_parser(_command_of(argv))
    args = parser.parse_args(argv)
    if args.command is None:
        args.func = cmd_report
    try:
        args.cache_in_use = None if args.command == "cache" else _compilation_cache(args)
        return int(args.func(args) or 0)
    except PolyjaxError as e:
        print(f"polyjax: error: {e}", file=sys.stderr)
        return 2
    finally:
        _trim(getattr(args, "cache_in_use", None))


def _trim(folder) -> None:
    """The cache folder's size cap, applied after a run that used it (:mod:`polyjax._cache_admin`)."""
    if folder is None:
        return
    from ._cache_admin import cache_cap_bytes, trim_cache
    from ._errors import InputError

    try:
        trim_cache(folder, cache_cap_bytes())
    except InputError as e:
        print(f"polyjax: warning: cache not trimmed: {e}", file=sys.stderr)


if __name__ == "__main__":
    sys.exit(main())
