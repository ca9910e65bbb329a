r"""``polyjax export FIT_OR_DATA --to gltf|mitsuba-xml``: a standard material fitted to a saved model or a measured
data set, written in that format, with the error the projection onto the standard model costs (for Mitsuba XML
the plugin chosen by :mod:`polyjax.export._mitsuba_choice`).

The standard model is fitted by the package that provides it (``baselines``, found through its registered model
kind, :func:`polyjax._io.fitter_for`): R, G, B jointly, paper equation (11) with the 80-degree cutoff. A saved
model is tabulated first at ``--samples`` random direction pairs (uniform in solid angle, equal weights, a quarter
of the views near the mirror direction so that glossy lobes are sampled), a data set (``merl-nbrdf:<name>``,
``merl:<file>``, ``rgl:<file>``, ``cornell:<name>``, ...) is used as loaded; a data set on the MERL grid
(:data:`polyjax.cli._args.SUBSAMPLED_KINDS`) on a seeded subsample of
:data:`polyjax.cli._args.DEFAULT_SUBSAMPLE` of its bins unless ``--subsample``
says otherwise (``all``: every bin, 1.1 M of them, minutes and gigabytes). The default loses little: on the full grid
the material fitted to 20,000 bins has an L2 and a log-space error within a few per cent of the one fitted to every
bin (``benchmarks/RESULTS.md``, "Standard exports of measured data: the default subsample").

A saved capture fit (:class:`polyjax.CaptureFit`) exported ``--to gltf`` is written as a ``.glb`` card instead
(:mod:`polyjax.cli._capture_out`, :func:`polyjax.export.gltf_card`): the image plane as a quad with the fit's
glTF maps as textures.

Printed: the L2 of equation (11) per channel, relative to the data's own L2, and the same weighted L2 of
``log(1 + f cos theta_u)`` (a log-space error that weighs dark and bright parts alike).
"""

from __future__ import annotations

from pathlib import Path

import jax
import numpy as np

import polyjax as pj

from .. import export
from .._files import check_output_path
from .._io import fitter_for
from ..export._mitsuba_choice import PLUGINS, TOLERANCE, fit_plugin
from ._args import add_subsample_option, check_subsample, subsample_option
from ._capture_out import capture_fit_of, run_card_export
from ._progress import progress_line

#: target -> (standard model fitted, writer in :mod:`polyjax.export`, default suffix)
TARGETS: dict[str, tuple[str, str, str]] = {
    "gltf": ("gltf-pbr", "gltf", ".glb"),
    "mitsuba-xml": ("principled", "mitsuba_xml", ".xml"),
    "openpbr": ("openpbr", "materialx", ".mtlx"),
    "usd": ("usd-preview", "usd", ".usda"),
}


def add_standard_arguments(p) -> None:
    """The options of the standard targets, added to ``polyjax export``'s parser."""
    p.add_argument("--samples", type=int, default=20000,
                   help="direction pairs a saved model is tabulated at (--to gltf, mitsuba-xml, openpbr, usd)")
    add_subsample_option(p, "minutes and gigabytes to fit (--to gltf, mitsuba-xml, openpbr, usd)")
    p.add_argument("--plugin", default="auto", choices=("auto",) + PLUGINS,
                   help="the Mitsuba plugin written (--to mitsuba-xml); auto: the simplest of "
                   f"{', '.join(PLUGINS)} whose L2 is within --tolerance of principled's")
    p.add_argument("--tolerance", type=float, default=TOLERANCE,
                   help=f"--plugin auto: how much larger than principled's L2 a simpler plugin's may be ({TOLERANCE})")
    p.add_argument("--full-image", action="store_true",
                   help="--to gltf of a capture fit: the card's quad covers the whole image (default: the mask's box)")


def _tabulated(model, n: int, seed: int = 0):
    """``(u, v, values (*batch, n))`` of a saved model at ``n`` random pairs (see the module docs)."""
    rng = np.random.default_rng(seed)

    def dirs(k):
        w = rng.normal(size=(k, 3))
        w[:, 2] = np.abs(w[:, 2])
        return w / np.linalg.norm(w, axis=1, keepdims=True)

    u, v = dirs(n), dirs(n)
    k = n // 4
    mirror = u[:k] * np.array([-1.0, -1.0, 1.0]) + 0.08 * rng.normal(size=(k, 3))
    mirror[:, 2] = np.abs(mirror[:, 2]) + 0.05
    v[:k] = mirror / np.linalg.norm(mirror, axis=1, keepdims=True)
    return u, v, np.asarray(model(u, v), float)


def _source(args):
    """The measurements to fit: a saved model tabulated, or a data set; values ``(*batch, 3, n)``."""
    src = str(args.model)
    if Path(src).suffix.lower() in (".npz", ".json") and Path(src).exists():
        if not isinstance(args.samples, int) or args.samples < 100:
            raise pj.InputError(f"--samples: expected an integer >= 100, found {args.samples!r}")
        u, v, values = _tabulated(pj.load_model(src), args.samples)
        data = pj.make_measurements(u, v, values, source=src)
    else:
        src = pj.data.dataset_spec(src)
        data = pj.data.load(src, root=getattr(args, "data_root", None), **subsample_option(args.subsample, src))
    return _one_material(data, args.index, src)


def _one_material(data, index, src):
    """``data`` with values ``(3, n)``: a grey model's channel repeated, a batch's material ``index``."""
    values = np.asarray(data.values)
    n = values.shape[-1]
    if values.ndim == 1 or values.shape[:-1] == (1,):
        rgb, i = np.broadcast_to(values.reshape(1, n), (3, n)), None
    elif values.shape[-2] == 3:
        lanes = values.reshape(-1, 3, n)
        if index is None and lanes.shape[0] > 1:
            raise pj.InputError(f"{src}: holds {lanes.shape[0]} materials; choose one with --index")
        i = 0 if index is None else int(index)
        if not -lanes.shape[0] <= i < lanes.shape[0]:
            raise pj.InputError(f"--index: expected a material in [0, {lanes.shape[0]}), found {index}")
        rgb = lanes[i]
    else:
        raise pj.InputError(f"{src}: expected values with an R, G, B channel axis (..., 3, n), found {values.shape}")

    def lane(a):  # weights, mask: (n,) or per lane
        a = np.asarray(a)
        return a if a.ndim == 1 or i is None else a.reshape(-1, 3, n)[i]

    return pj.make_measurements(np.asarray(data.u), np.asarray(data.v), rgb, weights=lane(data.weights),
                                mask=lane(data.mask))


def run_standard_export(args) -> int:
    """Fit the target's standard model to ``args.model`` and write it (see the module docs)."""
    jax.config.update("jax_enable_x64", True)
    name, writer, suffix = TARGETS[args.to]
    src = str(args.model)
    base = src.partition(":")[2] if ":" in src and not Path(src).exists() else src  # "rgl:satin" -> "satin"
    out = check_output_path(Path(args.out) if args.out else Path(Path(base.split(",")[0].strip()).stem + suffix),
                            "--out")
    capture_fit = capture_fit_of(str(args.model)) if args.to == "gltf" else None
    if capture_fit is not None:  # a capture fit: the .glb card of its maps
        return run_card_export(args, capture_fit, out)
    kind, model_name = fitter_for(name)
    check_subsample(args.subsample)  # checked before any work
    with progress_line(f"loading {args.model}"):
        data = _source(args)
    what = ", ".join(PLUGINS) if args.to == "mitsuba-xml" and args.plugin == "auto" else model_name
    print(f"fitting {what} to {data.values.shape[-1]} samples of {args.model} ...", flush=True)
    with progress_line(f"fitting {what}"):
        if args.to == "mitsuba-xml":  # the simplest Mitsuba plugin that fits as well as principled
            model_name, fit = fit_plugin(data, args.plugin, args.tolerance)
        else:
            fit = kind.fit(model_name, data)
    pred = np.asarray(fit(np.asarray(data.u), np.asarray(data.v)))
    values = np.asarray(data.values)
    l2 = np.asarray(fit.l2)
    own = np.asarray(pj.l2_error(values, np.zeros_like(values), data.u, data.v, weights=data.weights,
                                 mask=data.mask))
    lg = np.asarray(pj.log_error(values, pred, data.u, data.v, data.weights, cutoff_deg=80.0, mask=data.mask))
    getattr(export, writer)(fit.material(), out)
    print(f"{model_name} fitted to {args.model} (status {[int(s) for s in np.asarray(fit.status)]}):")
    print("  L2 (eq. 11) R, G, B: " + ", ".join(f"{x:.4g}" for x in l2)
          + "  (relative: " + ", ".join(f"{x:.3g}" for x in l2 / np.maximum(own, 1e-300)) + ")")
    print("  log-space L2 R, G, B: " + ", ".join(f"{x:.4g}" for x in lg))
    print(f"wrote {out} ({args.to})")
    return 0
