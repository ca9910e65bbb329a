"""What every command shares: the options of every command (data root, cache), the polynomial model's definition
(``--variables --degree --basis --interactions --link --eps``: one :class:`polyjax.PolynomialSpec`), degrees, dataset
specs, the samples a fit keeps, the image options of ``render`` and ``view``, strict JSON output."""

from __future__ import annotations

import argparse
import json
import math

import numpy as np

import polyjax as pj

from .._basis import n_terms
from .._config import configured_data_root
from .._errors import InputError, UnknownNameError
from .._model import LINKS, PolynomialSpec
from .._variables import get_variables

#: the built-in variable sets (pj.variable_sets() without importing JAX to print --help)
BUILTIN_VARIABLES = ("lafortune", "lafortune-anisotropic", "ward", "ashikhmin-shirley", "rusinkiewicz",
                     "rusinkiewicz-phid")


#: the folders below the data root that polyjax and baselines read
DATA_FOLDERS = ("curet/", "cornell/", "nbrdf_sztrajman2021/", "rgl_epfl/", "published_fits/")
ROOT_HELP = (f"measured data folder holding {', '.join(DATA_FOLDERS[:-1])} and {DATA_FOLDERS[-1]} (default: "
             "$POLYJAX_DATA); a folder given that does not exist is an error")
CACHE_HELP = ("folder of JAX's persistent compilation cache, which lets later runs skip compiling (default: "
              "$POLYJAX_CACHE, else $XDG_CACHE_HOME/polyjax/jax or ~/.cache/polyjax/jax); a folder polyjax creates "
              "is its own (mode 0700, a marker file): only its own entries there are ever trimmed or cleared, and "
              "nothing in a folder it did not create")
NO_CACHE_HELP = "do not read or write the compilation cache (also: POLYJAX_CACHE=off)"


class Parser(argparse.ArgumentParser):
    """The command line's parser: an abbreviation matching several spellings of one option (``--degre`` for
    ``--degree`` / ``--degrees``) is that option, not ambiguous, and every parse error is one line on stderr,
    ``polyjax: error: ...`` (exit status 2), as ``docs/command-line.md`` promises."""

    def _get_option_tuples(self, option_string):
        seen, out = set(), []
        for tup in super()._get_option_tuples(option_string):
            if id(tup[0]) not in seen:  # one entry per option, whatever its aliases
                seen.add(id(tup[0]))
                out.append(tup)
        return out

    def error(self, message):
        """One line on stderr, ``polyjax: error: <message>`` (the usage is in ``--help``), then exit 2."""
        self.exit(2, f"polyjax: error: {message.splitlines()[0] if message else 'bad arguments'} (see "
                  f"{self.prog} --help)\n")


def add_global_options(p: argparse.ArgumentParser, default=None) -> argparse.ArgumentParser:
    """``--data-root``, ``--cache-dir``, ``--no-cache`` on ``p``: the main parser (``default`` None) or the parent
    parser of every command (``argparse.SUPPRESS``: a value given before the command is kept)."""
    p.add_argument("--data-root", default=default, help=ROOT_HELP)
    p.add_argument("--cache-dir", default=default, help=CACHE_HELP)
    p.add_argument("--no-cache", action="store_true", default=False if default is None else default,
                   help=NO_CACHE_HELP)
    return p


def add_image_options(p: argparse.ArgumentParser, size_help: str, exposure_help: str) -> None:
    """``--size`` (pixels, default 256) and ``--exposure`` (stops, default 0) of the commands that make images."""
    p.add_argument("--size", type=int, default=256, help=size_help)
    p.add_argument("--exposure", type=float, default=0.0, help=exposure_help)


def add_model_options(p: argparse.ArgumentParser, defaults: PolynomialSpec, *, several: bool = False,
                      degree_default: str | None = None) -> None:
    """The polynomial model's definition on ``p``, with the command's ``defaults``: ``--variables``, ``--degree``
    (``--degrees``; comma-separated degrees when ``several``), ``--basis``, ``--interactions`` /
    ``--no-interactions``, ``--link``, ``--eps``, ``--clamp`` / ``--no-clamp``; :func:`spec_from_args` reads them
    back. ``degree_default``: the help's words for a command whose ``--degree`` left out is None (the command then
    chooses it) rather than ``defaults.degree``."""
    degrees = ",".join(map(str, defaults.degree)) if isinstance(defaults.degree, tuple) else str(defaults.degree)
    p.add_argument("--variables", default=defaults.variables,
                   help="explanatory variable set: " + " | ".join(BUILTIN_VARIABLES)
                   + f" (default {defaults.variables})")
    p.add_argument("--degree", "--degrees", dest="degree", default=degrees if degree_default is None else None,
                   help="polynomial degree p" + (", or comma-separated degrees fitted in one batch (e.g. 2,3,5)"
                                                 if several else "") + f"; default {degree_default or degrees}")
    p.add_argument("--basis", default=defaults.basis, choices=["legendre", "monomial"],
                   help=f"basis of the solve: scaled Legendre (well conditioned) or the paper's monomials "
                   f"(default {defaults.basis})")
    p.add_argument("--interactions", action=argparse.BooleanOptionalAction, default=defaults.interactions,
                   help="the full response surface of equation (2), or equation (3) with --no-interactions "
                   f"(default: {'with' if defaults.interactions else 'without'})")
    p.add_argument("--link", default=defaults.link, choices=list(LINKS),
                   help="identity: the closed-form fit of equation (3); log: f = exp(P) - eps, fitted by a few "
                   f"Gauss-Newton solves (default {defaults.link})")
    p.add_argument("--eps", type=float, default=defaults.eps,
                   help=f"the log link's offset in 1/sr (default {defaults.eps:g})")
    p.add_argument("--clamp", action=argparse.BooleanOptionalAction, default=defaults.clamp,
                   help="evaluate the polynomial at its components clamped to the fitted samples' box, bounded under "
                   "directions unlike the fitted ones (Legendre basis; default: "
                   f"{'clamped' if defaults.clamp else 'not clamped'})")


def spec_from_args(args, *, several: bool = False, flag: str = "--degree") -> PolynomialSpec:
    """The :class:`polyjax.PolynomialSpec` of the options of :func:`add_model_options` (checked: InputError naming
    the flag; ``flag`` is the degree's, as the command documents it)."""
    degrees = parse_degrees(args.degree, flag)
    if len(degrees) > 1 and not several:
        raise InputError(f"{flag}: expected one degree for this command, found {args.degree!r}")
    try:
        return PolynomialSpec(args.variables, degrees[0] if len(degrees) == 1 else tuple(degrees), args.basis,
                              args.interactions, args.link, args.eps, args.clamp)
    except (InputError, UnknownNameError) as e:
        raise type(e)(f"--{e}") from None


#: the samples of a data set on the MERL grid that ``polyjax fit`` and a standard export use unless ``--subsample``
#: says otherwise (``benchmarks/RESULTS.md``: "the default subsample")
DEFAULT_SUBSAMPLE = 20000
#: the data set kinds on the MERL grid (1,111,432 bins), subsampled by default
SUBSAMPLED_KINDS = ("merl", "merl-nbrdf", "merl_nbrdf", "nbrdf", "rgl")


def add_subsample_option(p: argparse.ArgumentParser, cost: str) -> None:
    """``--subsample`` on the parser ``p``; ``cost``: what every bin costs the command, for the help."""
    p.add_argument("--subsample", default=None,
                   help=f"keep this many samples of a measured data set, or 'all' (default {DEFAULT_SUBSAMPLE} of a "
                   f"data set on the MERL grid: merl:, merl-nbrdf:, nbrdf:, rgl:, whose 1.1 M bins take {cost}, "
                   "for a model within a few per cent of the same error; other data sets: all)")


def check_subsample(text) -> int | None:
    """``--subsample`` parsed before any work: None (not given, or ``all``) or a count of at least 100.

    Raises:
        InputError: anything else, naming the option and what it expects.
    """
    if text is None or str(text).strip().lower() == "all":
        return None
    try:
        n = int(str(text))
    except ValueError:
        n = 0
    if n < 100:
        raise InputError(f"--subsample: expected an integer >= 100 or 'all', found {text!r}")
    return n


def subsample_option(text, spec: str) -> dict:
    """The loader's ``subsample`` option of ``--subsample`` (``text``: None, an integer, or ``all``) for the data
    set ``spec``: :data:`DEFAULT_SUBSAMPLE` for a data set on the MERL grid when not given, nothing for ``all`` or
    for another data set when not given.

    Raises:
        InputError: a bad value, or a count for a data set that is not on the MERL grid (its loader has no
            subsample).
    """
    n = check_subsample(text)
    kind = pj.data.dataset_spec(spec).partition(":")[0].strip().lower() if spec else ""
    grid = kind in SUBSAMPLED_KINDS
    if text is None:
        return {"subsample": DEFAULT_SUBSAMPLE} if grid else {}
    if n is not None and not grid:
        raise InputError(f"--subsample: applies to data sets on the MERL grid ({', '.join(SUBSAMPLED_KINDS)}), "
                         f"found {spec!r}")
    return {} if n is None else {"subsample": n}


def load_dataset(args):
    """Measurements from --dataset / --sample, or the synthetic default when no data root is configured at all.

    A data set on the MERL grid is subsampled as ``--subsample`` says (:func:`subsample_option`). A data root that
    is given (``--data-root`` or ``$POLYJAX_DATA``) but does not exist is an error.
    """
    text = getattr(args, "subsample", None)
    if args.dataset:
        return pj.data.load(args.dataset, root=args.data_root, **subsample_option(text, args.dataset)), False
    if check_subsample(text) is not None:
        raise InputError(f"--subsample: applies to --dataset on the MERL grid, not to --sample (CUReT), found "
                         f"{text!r}")
    if configured_data_root(args.data_root) is not None:
        return pj.data.load_curet(args.data_root, [args.sample]), False
    return pj.data.synthetic_default(), True


def parse_degrees(text, flag: str = "--degree") -> list[int]:
    """``"7"`` or ``"2,3,5"`` -> a list of non-negative integers; InputError naming ``flag`` otherwise."""
    try:
        degrees = [int(d) for d in str(text).split(",") if d.strip()]
    except ValueError:
        degrees = []
    if not degrees or min(degrees) < 0:
        raise InputError(f"{flag}: expected a degree or comma-separated degrees (e.g. 5 or 2,3,5), found {text!r}")
    return degrees


def samples_used(data, cutoff) -> int:
    """The fewest samples any lane of ``data`` keeps: inside the grazing cutoff (the rule of
    :func:`polyjax.cutoff_mask`), valid in its mask, with a positive weight (numpy on the host: nothing compiled)."""
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
    vs = get_variables(variables)
    n = samples_used(data, cutoff)
    for p in degrees:
        m = n_terms(vs.k, int(p), bool(interactions))
        if m > n:
            ok = [q for q in range(int(p), -1, -1) if n_terms(vs.k, q, bool(interactions)) <= n]
            hint = f"; degree {ok[0]} or lower fits" if ok else ""
            raise InputError(f"{flag} {p}: expected at most as many parameters as the {n} samples used (inside "
                             f"the {cutoff} degree cutoff), found {m} parameters ({vs.name} variables{hint})")


def _finite_or_none(x):
    if isinstance(x, float):
        return x if math.isfinite(x) else None
    if isinstance(x, dict):
        return {k: _finite_or_none(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_finite_or_none(v) for v in x]
    return x


def strict_json(record) -> str:
    """``record`` as strict JSON (RFC 8259, which has no ``Infinity`` or ``NaN``): every non-finite float becomes
    ``null`` (e.g. the condition number of a rank-deficient fit, the PSNR of an exact re-rendering)."""
    return json.dumps(_finite_or_none(record), allow_nan=False)
