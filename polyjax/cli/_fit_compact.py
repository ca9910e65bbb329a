"""``polyjax fit --budget N`` (and ``polyjax fit`` with no model options on RGB data): the compact fit of
:func:`polyjax.fit_compact`, its report (text, or one JSON object with ``--json``) and its saving."""

from __future__ import annotations

import time

import numpy as np

import polyjax as pj

from .._compact.fit import DEFAULT_BUDGET, METRICS
from .._errors import InputError
from ._args import strict_json
from ._progress import compile_notice, progress_line

#: the model options of ``polyjax fit`` (argparse destinations) that choose the paper's polynomial or a baseline
MODEL_OPTIONS = ("variables", "degree", "basis", "interactions", "link", "eps", "clamp")


def add_compact_options(f) -> None:
    """``--budget`` and ``--metric`` on the ``fit`` parser."""
    f.add_argument("--budget", type=int, default=None,
                   help="fit the most accurate compact model of at most this many numbers per material (all three "
                   "channels counted), chosen by cross-validation; RGB data only. With no model option (--model, "
                   "--variables, --degree, ...) on RGB data the fit is compact with budget "
                   f"{DEFAULT_BUDGET}")
    f.add_argument("--metric", default="log", choices=list(METRICS),
                   help="what the compact fit minimises and compares: the log metric (default) or the L2 of "
                   "equation (11)")


def is_rgb(data) -> bool:
    """RGB values ``(*batch, 3, n)`` with channels named R, G, B (or unnamed)."""
    shape = tuple(data.values.shape)
    return len(shape) >= 2 and shape[-2] == 3 and tuple(data.channels) in ((), ("R", "G", "B"))


def wants_compact(args, data, given: list[str]) -> bool:
    """Whether ``polyjax fit`` fits the compact model: ``--budget`` given, or no model option on RGB data.

    Raises:
        InputError: ``--budget`` with a model option, or on data that are not RGB.
    """
    if args.budget is None:
        return not given and args.model.strip().lower() == "polynomial" and is_rgb(data)
    if given or args.model.strip().lower() != "polynomial":
        opts = ", ".join(f"--{g}" for g in given) or f"--model {args.model}"
        raise InputError(f"--budget: chooses the model itself; expected no model option with it, found {opts}")
    if not is_rgb(data):
        raise InputError(f"--budget: expected RGB data (values (*batch, 3, n)), found values "
                         f"{tuple(data.values.shape)} with channels {list(data.channels)} from {data.source}")
    return True


def run_compact(args, data) -> int:
    """Fit, report and optionally save the compact model; returns the exit status."""
    budget = DEFAULT_BUDGET if args.budget is None else args.budget
    t0 = time.perf_counter()
    with compile_notice("the fit", getattr(args, "cache_in_use", None)), progress_line("fitting compact"):
        model = pj.fit_compact(data, budget, metric=args.metric)
        np.asarray(model.l2)
    elapsed = time.perf_counter() - t0
    names = list(data.names) if len(data.names) else [""]
    out = {"source": data.source, "model": "compact", "budget": budget, "metric": args.metric,
           "family": model.family, "config": repr(model.config), "n_numbers": model.n_numbers,
           "n_samples": data.n_samples, "names": names, "l2": np.asarray(model.l2).tolist(),
           "log": np.asarray(model.log).tolist(),
           "seconds": elapsed}
    if args.save:
        out["saved"] = str(pj.save_model(args.save, model, metadata={"fit_seconds": elapsed, "fit_command": "fit"}))
    if args.json:
        print(strict_json(out))
        return 0
    print(f"data: {out['source']}, {out['n_samples']} samples")
    print(f"model: compact, family {model.family}, config {out['config']}, {model.n_numbers} numbers per material "
          f"(budget {budget}, chosen by {args.metric} held-out error)")
    for name, l2, lg in zip(names, np.ravel(out["l2"]), np.ravel(out["log"])):
        print(f"  {name:<28s} held-out L2 = {l2:.5f}   log = {lg:.5f}")
    print(f"fit time (including compilation): {elapsed:.3f} s")
    if out.get("saved"):
        print(f"model written to {out['saved']}")
    return 0
