"""The ``polyjax render`` command: spheres (or a models x materials grid) of fitted models, with the
measured reference, written as EXR (linear) and PNG (sRGB preview)."""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path

import jax
import numpy as np

import polyjax as pj

from .._config import check_output_file, configured_data_root
from .._errors import InputError
from .._io import fitter_for
from ..render import (
    Camera,
    DirectionalLight,
    PointLight,
    Scene,
    Sphere,
    SwapUV,
    comparison_figure,
    load_envmap,
    mosaic,
    procedural_sky,
    render_grid,
    rgb_brdf,
    write_exr,
    write_png,
)
from ..render._brdf import TabulatedBRDF
from ._args import add_image_options, add_model_options, check_degrees_fit, spec_from_args


def add_render_parser(subparsers, parents=()) -> argparse.ArgumentParser:
    """Add the ``render`` subcommand to an ``argparse`` subparsers object and return its parser."""
    r = subparsers.add_parser(
        "render", parents=list(parents),
        help="render spheres of fitted models (and the measured reference) to EXR + PNG",
        description="Fit the polynomial model to a dataset and render one sphere per degree and material "
        "(a grid like the paper's Fig. 3), optionally beside the measured reference (neural MERL evaluated "
        "directly, other data interpolated), with PSNR against the reference.",
    )
    r.add_argument("--dataset", default=None,
                   help="dataset spec, e.g. curet:25,33 or merl-nbrdf:green-latex (default: curet:25 with a data "
                        "root, else the built-in synthetic set)")
    add_model_options(r, pj.PolynomialSpec("lafortune", 5), several=True)  # several degrees: one grid row each
    r.add_argument("--model", default=None,
                   help="a saved model file (.npz/.json of polyjax.save_model: polynomial or baseline fit; it must "
                   "hold as many materials as --dataset), or a baseline model name as in `fit --model` (e.g. "
                   "cook-torrance) fitted to --dataset; rendered instead of the polynomial degrees")
    r.add_argument("--reference", action="store_true", help="add the measured data as the first row, and PSNR")
    r.add_argument("--light", default="point",
                   help="point | directional | sky (procedural environment) | path to a lat-long .exr map")
    add_image_options(r, size_help="pixels per sphere", exposure_help="PNG exposure in stops")
    r.add_argument("--spp", type=int, default=64, help="environment samples per pixel")
    r.add_argument("--swap-uv", action="store_true", help="exchange light and view (reciprocity check, Fig. 8)")
    r.add_argument("--out", default="render", help="output prefix: writes <out>.exr and <out>.png")
    return r


def _lights(spec: str):
    if spec == "point":
        return [PointLight(position=(2.0, 2.0, 4.0), intensity=24.0)]
    if spec == "directional":
        return [DirectionalLight(direction=(1.0, 1.0, 1.5), irradiance=np.pi)]
    if spec == "sky":
        return [procedural_sky()]
    return [load_envmap(spec)]


def _reference(spec: str, m, k: int, root):
    """The measured BRDF of material ``k``: the neural MERL network itself, or interpolated samples."""
    kind, _, _ = spec.partition(":")
    if kind.strip().lower() == "merl-nbrdf" and hasattr(pj.data, "load_nbrdf"):
        names = list(m.names) if m.names else [spec.partition(":")[2]]
        return pj.data.load_nbrdf(names[k], root=root)
    has_channels = bool(m.axes) and m.axes[-1] == "channel"
    vals = np.asarray(m.values)
    keep = np.ones(vals.shape, bool) if m.mask is None else np.broadcast_to(np.asarray(m.mask), vals.shape)
    lead = 2 if has_channels else 1
    vals = vals.reshape((-1,) + vals.shape[vals.ndim - lead:])[k]  # (C, n) or (n,)
    keep = keep.reshape((-1,) + keep.shape[keep.ndim - lead:])[k]
    if has_channels:
        keep = np.all(keep, axis=0)
        vals = vals.T if vals.shape[0] == 3 else vals[0]
    u, v = np.asarray(m.u)[keep], np.asarray(m.v)[keep]
    vals = vals[keep]
    return TabulatedBRDF(u, v, vals)


def run_render(args) -> int:
    """Run ``polyjax render`` from parsed arguments; returns the exit status."""
    root = getattr(args, "data_root", None)
    out = Path(args.out)
    check_output_file(out.with_suffix(".exr"), "--out")
    check_output_file(out.with_suffix(".png"), "--out")
    model_spec = spec_from_args(args, several=True, flag="--degrees")
    degrees = list(model_spec.degree) if isinstance(model_spec.degree, tuple) else [model_spec.degree]
    spec = args.dataset or ("curet:25" if configured_data_root(root) is not None else "synthetic")
    m = pj.data.synthetic_default() if spec == "synthetic" else pj.data.load(spec, root)
    if not args.model or args.model.strip().lower() == "polynomial":
        check_degrees_fit(m, model_spec.variables, degrees, model_spec.interactions, 80.0, "--degrees")
    has_channels = bool(m.axes) and m.axes[-1] == "channel"
    vals = np.asarray(m.values)
    n_mat = int(np.prod(vals.shape[: vals.ndim - (2 if has_channels else 1)], dtype=int))
    names = list(m.names) if m.names else [spec]
    rows, row_names = _rows(args, m, spec, root, model_spec, degrees, n_mat, has_channels)
    if args.swap_uv:
        rows = [[SwapUV(b) for b in row] for row in rows]
    cam = Camera(eye=(0.0, 0.0, 5.0), width=args.size, height=args.size, ortho_height=2.1)
    scene = Scene(cam, [Sphere(rows[0][0])], _lights(args.light))
    grid = render_grid(rows, scene, spp=args.spp)
    images = np.asarray(grid.images, dtype=np.float32)
    big = mosaic(images, pad=2, fill=0.0)
    write_exr(out.with_suffix(".exr"), big)
    write_png(out.with_suffix(".png"), big, exposure=args.exposure)
    print(f"rows: {', '.join(row_names)}; columns: {', '.join(names[:n_mat])}")
    print(f"effects: {', '.join(grid.effects.names())}; wrote {out.with_suffix('.exr')} and {out.with_suffix('.png')}")
    if args.reference and len(rows) > 1:
        _compare(out, images, np.asarray(grid.hit), row_names, names, n_mat, args.exposure)
    return 0


def _rows(args, m, spec: str, root, model_spec, degrees, n_mat: int, has_channels: bool):
    """The grid's rows (one RGB BRDF per material each) and their names: the measured reference with
    ``--reference``, then the ``--model`` (a saved file or a baseline fitted to ``m``) or one polynomial fit per
    degree."""
    saved = None  # the --model row, made first: a model that does not match the dataset fails before any work
    if args.model and args.model.strip().lower() != "polynomial":
        is_file = Path(args.model).suffix in (".npz", ".json") or Path(args.model).exists()
        if is_file:
            model, row_name = pj.load_model(args.model), Path(args.model).stem
        else:
            kind, model_name = fitter_for(args.model)
            model, row_name = kind.fit(model_name, m), model_name
        saved = _lanes(model, n_mat, has_channels, args.model, spec)
    rows, row_names = [], []
    if args.reference:
        rows.append([_reference(spec, m, k, root) for k in range(n_mat)])
        row_names.append("measured")
    if saved is not None:
        rows.append(saved)
        row_names.append(row_name)
    else:
        for p in degrees:
            model = pj.fit_polynomial(m, spec=dataclasses.replace(model_spec, degree=p))
            rows.append(_lanes(model, n_mat, has_channels, args.model, spec))
            row_names.append(f"p={p}")
    return rows, row_names


def _lanes(model, n_mat: int, has_channels: bool, model_arg, spec: str):
    """One RGB BRDF per material of a model with batch shape (materials..., [channels])."""
    nb = len(model.batch_shape) - (1 if has_channels else 0)
    n_model = int(np.prod(model.batch_shape[:max(nb, 0)], dtype=int))
    if n_model != n_mat:
        raise InputError(
            f"--model {model_arg!r}: holds {n_model} material(s) (batch shape {model.batch_shape}), but the "
            f"dataset {spec!r} has {n_mat}; pass the --dataset the model was fitted to"
        )
    if nb <= 0:
        return [rgb_brdf(model)]
    flat = jax.tree.map(lambda a: a.reshape((-1,) + a.shape[nb:]), model)
    return [rgb_brdf(jax.tree.map(lambda a, k=k: a[k], flat)) for k in range(n_mat)]


def _compare(out: Path, images, hit, row_names, names, n_mat: int, exposure: float) -> None:
    """One comparison figure per material (``<out>_<k>_compare.png``, ``<out>`` less its suffix, as for the EXR
    and the PNG), the measured row against the others, with their PSNR printed."""
    for k in range(n_mat):
        fig = out.parent / f"{out.with_suffix('').name}_{k}_compare.png"
        scores = comparison_figure(fig, images[0, k], list(images[1:, k]), row_names[1:], exposure=exposure, mask=hit)
        print(f"{names[k] if k < len(names) else k}: PSNR vs measured " +
              ", ".join(f"{n} {s:.2f} dB" for n, s in scores.items()) + f"  ({fig})")


def add_parser(sub, common) -> None:
    """The ``render`` command's parser."""
    add_render_parser(sub, parents=[common]).set_defaults(func=run_render)
