"""``polyjax fit``: fit the polynomial model (or a baseline, ``--model``) to one dataset and report every lane's
L2, status and coefficients (text, or one JSON object with ``--json``)."""

from __future__ import annotations

import itertools
import time

import numpy as np

import polyjax as pj

from .._config import check_model_file
from .._fit.saved import fit_saved
from .._io import fitter_for, kind_of
from .._results import status_warnings
from ._args import (
    add_model_options,
    add_subsample_option,
    check_degrees_fit,
    load_dataset,
    spec_from_args,
    strict_json,
)
from ._fit_compact import MODEL_OPTIONS, add_compact_options, run_compact, wants_compact
from ._progress import compile_notice, progress_line

#: the model ``polyjax fit`` fits by default: Lafortune's variables, p = 7
DEFAULT_SPEC = pj.PolynomialSpec("lafortune", 7)


def add_parser(sub, common) -> None:
    """The ``fit`` command's parser."""
    f = sub.add_parser("fit", parents=[common], help="fit a model to one dataset and print L2 and coefficients",
                       description="Fit the polynomial model (or a baseline model, --model) to a dataset; one row per "
                       "fitted lane (degree x material x channel).")
    f.add_argument("--sample", default="25", help="CUReT sample number or name (default 25, Quarry Tile)")
    f.add_argument("--dataset", default=None,
                   help="dataset spec instead of --sample, e.g. curet:1,25, merl-nbrdf:green-latex, cornell:cayman, "
                   "merl:<file.binary>, nbrdf:<zip or folder>:<name>, rgl:<file.bsdf>")
    f.add_argument("--model", default="polynomial",
                   help="polynomial (default) or a baseline model, e.g. cook-torrance, ward, lafortune (any name of "
                   "baselines.MODELS); --variables, --degree, --basis, --interactions, --link, --eps apply to the "
                   "polynomial only")
    add_model_options(f, DEFAULT_SPEC, several=True)
    f.set_defaults(**{k: None for k in MODEL_OPTIONS})  # None: not given (the defaults follow the data, cmd_fit)
    add_compact_options(f)
    add_subsample_option(f, "40 s and 5 GB to fit compactly against 6 s and 0.6 GB")
    f.add_argument("--cutoff", type=float, default=80.0, help="grazing cutoff in degrees (default 80)")
    f.add_argument("--save", default=None, help="write the fitted model (.npz or .json; format in README)")
    f.add_argument("--json", action="store_true", help="machine-readable output")
    f.set_defaults(func=cmd_fit)



def _lane_labels(data, lead: list[str] | None = None) -> list[str]:
    """One label per fitted lane, in C order over (leading labels, data batch axes): e.g. ``"p=2 alpha R"``.

    A material axis is labelled by ``data.names``, a channel axis by ``data.channels``; data without a material
    axis that names its one material (a single file) gets that name in front.
    """
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


#: a fit whose L2 is above this fraction of the L2 of f = 0 is reported as barely better than no model
ZERO_MODEL_RATIO = 0.95


def cmd_fit(args) -> int:
    """Run ``polyjax fit``: fit the model of ``--model`` to the dataset, optionally save it, and report every lane's
    L2, status and coefficients (text, or one JSON object with ``--json``); returns the exit status.

    With ``--budget``, or with no model option on RGB data, the compact fit instead (``_fit_compact``)."""
    given = _fill_model_defaults(args)
    spec = spec_from_args(args, several=True)
    degrees = list(spec.degree) if isinstance(spec.degree, tuple) else [spec.degree]
    degree = degrees[0] if len(degrees) == 1 else degrees
    polynomial = args.model.strip().lower() == "polynomial"
    kind, model_name = (None, "polynomial") if polynomial else fitter_for(args.model)
    if args.save:
        check_model_file(args.save, "--save")
    data, synthetic = load_dataset(args)
    if wants_compact(args, data, given):
        return run_compact(args, data)
    if polynomial:
        check_degrees_fit(data, spec.variables, degrees, spec.interactions, args.cutoff, "--degree")
    model, l2, zero, elapsed = _run_fit(args, data, kind, model_name, spec)
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


def _fill_model_defaults(args) -> list[str]:
    """The model options given on the command line (their destinations); the others set to :data:`DEFAULT_SPEC`."""
    given = [k for k in MODEL_OPTIONS if getattr(args, k) is not None]
    defaults = DEFAULT_SPEC.to_dict()
    for k in MODEL_OPTIONS:
        if getattr(args, k) is None:
            setattr(args, k, str(defaults[k]) if k == "degree" else defaults[k])
    return given


def _run_fit(args, data, kind, model_name, spec):
    """The fit of ``polyjax fit`` (``kind`` None: the polynomial) -> ``(model, l2 array, zero-model L2 or None,
    seconds)``. A polynomial fit runs from the executable saved beside the cache when there is one
    (``polyjax/_fit/saved.py``, which also returns the L2 of ``f = 0``), else through :func:`polyjax.fit_polynomial`."""
    t0 = time.perf_counter()
    cache = getattr(args, "cache_in_use", None)
    zero = None
    with compile_notice("the fit", cache), progress_line(f"fitting {model_name}"):
        if kind is None:
            degree = list(spec.degree) if isinstance(spec.degree, tuple) else spec.degree
            saved = None if spec.link != "identity" else fit_saved(
                data, cache, variables=spec.variables, degree=degree, basis=spec.basis,
                interactions=spec.interactions, cutoff_deg=args.cutoff)
            model, zero = saved if saved is not None else (pj.fit_polynomial(data, spec=spec,
                                                                            cutoff_deg=args.cutoff), None)
        else:
            model = kind.fit(model_name, data, cutoff_deg=args.cutoff)
        l2 = np.asarray(model.l2)
    return model, l2, zero, time.perf_counter() - t0


def _fit_record(args, data, synthetic, model, model_name, degrees, degree, l2, zero, elapsed):
    """The JSON record of ``polyjax fit`` and the coefficients (or parameters) as one array."""
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
    else:  # a lane that ended MAX_STEPS (or FAILED, NONFINITE) is named, as BaselineFit.warnings names it
        warnings_ += status_warnings(np.asarray(model.status), labels)
    out = {
        "source": data.source,
        "n_samples": data.n_samples,
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
        out["spec"] = model.spec.to_dict()
        out["rank"] = np.asarray(model.rank).tolist()
        out["condition"] = np.asarray(model.condition).tolist()
    return out, beta


#: a full-rank fit whose weighted design has a condition number above this is reported as ill-conditioned
ILL_CONDITIONED = 1e7


def _condition_warning(cond, status, labels) -> list[str]:
    """A warning naming the full-rank lanes whose condition number exceeds :data:`ILL_CONDITIONED`: the samples
    barely determine that many parameters (a property of the samples, the same in either basis)."""
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
    polynomial = out["model"] == "polynomial"
    n_params, status = out["n_params"], out["status"]
    print(f"data: {out['source']}, {out['n_samples']} samples")
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


