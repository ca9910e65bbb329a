"""``polyjax svbrdf``: simulate a capture, fit every texel, write the coefficient textures, re-render under a new
light; on one process or several (``--num-processes``, ``--process-id``, ``--coordinator``)."""

from __future__ import annotations

import argparse
import time

import jax
import jax.numpy as jnp
import numpy as np
from jax.experimental import multihost_utils

import polyjax as pj

from .. import svbrdf
from .._basis import n_terms
from .._config import check_output_dir
from .._errors import InputError
from .._files import write_npz_atomically
from .._variables import get_variables
from ..svbrdf import _distributed, photograph, relight, simulate_capture, write_texture_shards
from ..svbrdf._capture import spread_cameras
from ..svbrdf._shards import FORMATS, local_part
from ._args import strict_json


def _floats(text: str, n: int, flag: str) -> tuple[float, ...]:
    try:
        vals = tuple(float(t) for t in text.split(","))
    except ValueError:
        vals = ()
    if len(vals) != n:
        raise InputError(f"{flag}: expected {n} comma-separated numbers, found {text!r}")
    return vals


def _cameras(text: str | None):
    """``--cameras``: None (the default camera), an integer ``C`` or ``x,y,z;x,y,z...``."""
    if text is None:
        return None
    if text.strip().isdigit():
        if int(text) < 1:
            raise InputError(f"--cameras: expected at least one camera, found {text!r}")
        return spread_cameras(int(text))
    try:
        return [_floats(t, 3, "--cameras") for t in text.split(";")]
    except InputError:
        raise InputError(f"--cameras: expected an integer or x,y,z[;x,y,z...], found {text!r}") from None


def add_svbrdf_parser(sub, parents=()) -> argparse.ArgumentParser:
    p = sub.add_parser(
        "svbrdf", parents=list(parents), help="simulate an SVBRDF capture, fit every texel, write texture shards",
        description="Simulate photographs of a flat sample whose texels blend neural MERL materials, under point "
        "lights and one fixed camera or several (--cameras) (direct evaluation of f(u, v) E cos(theta_u) per "
        "texel); fit a polynomial BRDF "
        "to every texel in closed form; write the coefficient textures (one .npz and/or one multi-channel OpenEXR "
        "image per shard, and manifest.json); "
        "re-render under a new light and report the PSNR against the simulated photograph there.")
    p.add_argument("--size", type=int, default=64, help="texels per side (default 64)")
    p.add_argument("--lights", type=int, default=48, help="number of point lights of the capture (default 48)")
    p.add_argument("--cameras", default=None,
                   help="camera positions: an integer C (C cameras spread in elevation from 70 to 15 degrees and "
                   "in azimuth, svbrdf.spread_cameras) or x,y,z[;x,y,z...]; default one camera at 0,-1.5,2.5")
    p.add_argument("--materials", default="pink-fabric,pink-felt", help="comma-separated MERL names (neural fits)")
    p.add_argument("--variables", default="lafortune", help="explanatory variable set of the per-texel fits")
    p.add_argument("--degree", type=int, default=3, help="polynomial degree p of the per-texel fits (default 3)")
    p.add_argument("--new-light", default="0.7,0.9,2.2", help="x,y,z of the re-rendering light")
    p.add_argument("--out", required=True, help="output folder of the texture shards and manifest")
    p.add_argument("--format", default="npz,exr",
                   help="shard files: npz (exact), exr (float64 as float32 hi + lo channels) or both (default npz,exr)")
    p.add_argument("--coordinator", default="localhost:12355", help="host:port of process 0 (several processes)")
    p.add_argument("--num-processes", type=int, default=1,
                   help="processes of the jax.distributed run (default 1)")
    p.add_argument("--process-id", type=int, default=0, help="this process's index, 0 .. num-processes - 1")
    p.add_argument("--json", action="store_true", help="machine-readable summary")
    p.set_defaults(func=run_svbrdf)
    return p


def _check_samples_per_texel(args, cameras) -> None:
    """Refuse, before any work, per-texel fits with more parameters than a texel can have samples (one per light
    and camera): every texel's fit would fail."""
    n_cameras = 1 if cameras is None else len(cameras)
    m = n_terms(get_variables(args.variables).k, args.degree)
    if m > args.lights * n_cameras:
        raise InputError(f"--degree {args.degree}: expected at most as many parameters as the samples of a texel "
                         f"(--lights {args.lights} x {n_cameras} camera(s) = {args.lights * n_cameras}), found {m} "
                         f"parameters ({args.variables} variables): every texel's fit would fail; use a lower "
                         "--degree or more --lights")


def run_svbrdf(args) -> int:
    light = _floats(args.new_light, 3, "--new-light")  # argument errors before any work
    cameras = _cameras(args.cameras)
    formats = tuple(f.strip() for f in args.format.split(","))
    if not all(f in FORMATS for f in formats) or len(set(formats)) != len(formats):
        raise InputError(f"--format: expected npz, exr or npz,exr, found {args.format!r}")
    if args.lights < 1:
        raise InputError(f"--lights: expected at least one light, found {args.lights}")
    if args.size < 1:
        raise InputError(f"--size: expected at least one texel per side, found {args.size}")
    _check_samples_per_texel(args, cameras)
    check_output_dir(args.out, "--out")  # the one rule of every command: its parent folder must exist
    _distributed.initialize(args.coordinator, args.num_processes, args.process_id)  # before any JAX computation

    root = getattr(args, "data_root", None)
    names = [n.strip() for n in args.materials.split(",") if n.strip()]
    materials = [pj.data.load_nbrdf(n, root=root) for n in names]
    held = {}

    def load_rows(start, stop):
        kw = {} if cameras is None else dict(camera=cameras)
        cap = simulate_capture(materials, args.size, args.size, n_lights=args.lights, rows=slice(start, stop), **kw)
        held["capture"] = cap
        u, v, b, w = cap.observations()
        return dict(u=u, v=v, values=b, weights=w)

    t0 = time.perf_counter()
    model = svbrdf.fit_rows_distributed(load_rows, args.size, args.variables, args.degree)  # the package's own name
    jax.block_until_ready(model.coefficients)
    t_fit = time.perf_counter() - t0
    manifest = write_texture_shards(args.out, model, formats=formats)
    cap = held["capture"]
    mine = local_part(model)
    image, ref = relight(mine, cap, light), photograph(materials, cap, light)
    sse, count, peak = float(jnp.sum((image - ref) ** 2)), int(image.size), float(jnp.max(ref))
    write_npz_atomically(f"{args.out}/relit-rows-{cap.row0}-{cap.row0 + cap.positions.shape[0]}.npz",
                         relit=np.asarray(image), photograph=np.asarray(ref))
    if jax.process_count() > 1:
        parts = np.asarray(multihost_utils.process_allgather(np.array([sse, count, peak])))  # 3 scalars per process
        sse, count, peak = parts[:, 0].sum(), parts[:, 1].sum(), parts[:, 2].max()
    psnr = float(10 * np.log10(peak**2 / (sse / count))) if sse > 0 else float("inf")
    status = np.asarray(jnp.sum(mine.status != pj.RESULTS.OK))
    summary = dict(texels=args.size**2, cameras=1 if cap.camera.ndim == 1 else int(cap.camera.shape[0]),
                   processes=jax.process_count(), devices=jax.device_count(),
                   fit_seconds=t_fit, texels_per_second=args.size**2 / t_fit, psnr_new_light=psnr,
                   not_ok_local=int(status), manifest=str(manifest), materials=names,
                   warnings=[f"{int(status)} texel fits not OK"] if int(status) else [])
    if jax.process_index() == 0:
        if args.json:
            print(strict_json(summary))
        else:
            print(f"{summary['texels']} texels ({', '.join(names)}), {summary['processes']} process(es), "
                  f"{summary['devices']} device(s): fitted in {t_fit:.2f} s ({summary['texels_per_second']:.0f} "
                  f"texels/s, incl. compilation)")
            print(f"re-rendered under a new light at {light}: PSNR {psnr:.2f} dB against the simulated photograph")
            print(f"texture shards and manifest: {manifest}")
            if summary["not_ok_local"]:
                print(f"WARNING: {summary['not_ok_local']} of {mine.status.size} texel fits here are not OK "
                      f"(status other than OK: e.g. too few lit samples for degree {args.degree}); the PSNR above "
                      "includes them. Try a lower --degree or more --lights.")
    return 0


def add_parser(sub, common) -> None:
    """The ``svbrdf`` command's parser."""
    add_svbrdf_parser(sub, parents=[common])
