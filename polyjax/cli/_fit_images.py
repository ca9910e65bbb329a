"""The ``polyjax fit-images`` command: fit the polynomial BRDF to EXR photographs described by a JSON scene.

The scene file's format is documented in ``docs/fit-images.md`` (camera, objects, target, images and their lights,
paths relative to the file); ``polyjax fit-images --example DIR`` writes one with its images to start from.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

import polyjax as pj

from .._config import check_model_file, check_output_dir
from .._errors import DataFormatError, InputError, PolyjaxError
from .._files import inside_folder
from .._reading.bounded import load_json
from ..render import Camera, DirectionalLight, Lambertian, Plane, PointLight, Scene, Sphere, load_envmap, read_exr
from ..render._example_scene import write_example_scene
from ._args import add_model_options, spec_from_args, strict_json


def add_fit_images_parser(subparsers, parents=()) -> argparse.ArgumentParser:
    """Add the ``fit-images`` subcommand to an ``argparse`` subparsers object and return its parser."""
    p = subparsers.add_parser(
        "fit-images", parents=list(parents), help="fit the polynomial BRDF to EXR images of one object (JSON scene)",
        description="Fit the polynomial model of equation (3) to linear-RGB EXR images of one object with known "
        "geometry, camera and lights (a JSON scene description; format in docs/fit-images.md; --example DIR "
        "writes one to start from), in closed form.",
    )
    p.add_argument("scene", nargs="?", default=None,
                   help="JSON scene description listing the EXR images and their lights (format: docs/fit-images.md)")
    p.add_argument("--example", default=None, metavar="DIR",
                   help="write a ready example (scene.json and three EXR images of a Phong sphere) into DIR and "
                   "exit; then run: polyjax fit-images DIR/scene.json")
    add_model_options(p, pj.PolynomialSpec("lafortune", 5))
    p.add_argument("--saturation", type=float, default=None, help="exclude pixels with a channel at or above this")
    p.add_argument("--cutoff", type=float, default=80.0, help="grazing cutoff in degrees")
    p.add_argument("--spp", type=int, default=64, help="environment samples per pixel of the design")
    p.add_argument("--save", default=None, help="write the fitted model (.npz or .json, polyjax.save_model)")
    p.add_argument("--json", action="store_true", help="machine-readable output")
    p.set_defaults(func=run_fit_images)
    return p


def _object(d, where: str) -> dict:
    """``d`` when it is a JSON object, else an InputError naming ``where``."""
    if not isinstance(d, dict):
        raise InputError(f"{where}: expected a JSON object, found {type(d).__name__}")
    return d


def _list(d, where: str) -> list:
    """``d`` when it is a JSON list, else an InputError naming ``where``."""
    if not isinstance(d, list):
        raise InputError(f"{where}: expected a JSON list, found {type(d).__name__}")
    return d


def _field(d: dict, key: str, where: str, default=None, required=False):
    if key not in _object(d, where):
        if required:
            raise InputError(f"{where}: expected a field {key!r}")
        return default
    return d[key]


def _file(d: dict, where: str, path: Path, what: str) -> Path:
    """The file named by the field ``file`` of ``d``: a relative path inside the scene file's folder (else a
    :class:`polyjax.DataFormatError` naming ``path`` and ``what``)."""
    name = _field(d, "file", where, required=True)
    if not isinstance(name, str) or not name:
        raise InputError(f"{where}: file: expected a file name, found {name!r}")
    return inside_folder(path.parent, name, path, what)


def _read_spec(path: Path) -> dict:
    """The scene file's JSON object (its size within the input cap, nesting and integers bounded)."""
    if not path.is_file():
        raise InputError(f"{path}: scene file not found")
    try:
        spec = load_json(path, "a JSON scene description")
    except DataFormatError as e:
        raise InputError(f"{path}: expected JSON, {e.found}") from None
    if not isinstance(spec, dict):
        raise InputError(f"{path}: expected a JSON object with 'camera', 'objects', 'images'")
    return spec


def _camera(spec: dict, path: Path, images) -> Camera:
    cam_spec = dict(_object(_field(spec, "camera", str(path), required=True), f"{path}: camera"))
    for key in ("fov_deg", "width", "height", "ortho_height"):
        if key in cam_spec and (isinstance(cam_spec[key], bool) or not isinstance(cam_spec[key], (int, float))):
            raise InputError(f"{path}: camera.{key}: expected a number, found {cam_spec[key]!r}")
    cam_spec.setdefault("height", images[0].shape[0])
    cam_spec.setdefault("width", images[0].shape[1])
    try:
        return Camera(**cam_spec)
    except (TypeError, ValueError) as e:
        raise InputError(f"{path}: camera: {e}") from None


def _objects(spec: dict, path: Path) -> list:
    placeholder = Lambertian(0.5)
    objects = []
    for i, o in enumerate(_list(_field(spec, "objects", str(path), [{"type": "sphere"}]), f"{path}: objects")):
        kind = _object(o, f"{path}: objects[{i}]").get("type", "sphere")
        args = {k: v for k, v in o.items() if k != "type"}
        try:
            if kind == "sphere":
                objects.append(Sphere(placeholder, **args))
            elif kind == "plane":
                objects.append(Plane(placeholder, **args))
            else:
                raise InputError(f"{path}: objects[{i}]: expected type 'sphere' or 'plane', found {kind!r}")
        except (TypeError, ValueError) as e:
            raise InputError(f"{path}: objects[{i}]: {e}") from None
    return objects


def _lights(e: dict, path: Path, i: int) -> list:
    lights = []
    for j, li in enumerate(_list(_field(e, "lights", f"{path}: images[{i}]", required=True),
                                 f"{path}: images[{i}].lights")):
        where = f"{path}: images[{i}].lights[{j}]"
        kind = _object(li, where).get("type", "point")
        args = {k: v for k, v in li.items() if k != "type"}
        try:
            if kind == "point":
                lights.append(PointLight(**args))
            elif kind == "directional":
                lights.append(DirectionalLight(**args))
            elif kind == "environment":
                f = _file(args, where, path, f"images[{i}].lights[{j}].file")
                lights.append(load_envmap(f, float(args.get("scale", 1.0))))
            else:
                raise InputError(f"{where}: expected type 'point', 'directional' or 'environment', found {kind!r}")
        except (TypeError, ValueError) as err:
            if isinstance(err, PolyjaxError):
                raise
            raise InputError(f"{where}: {err}") from None
    return lights


def load_scene_json(path: str | Path):
    """Read a ``fit-images`` JSON description: ``(scenes, images, target)``. Every fault of the file (invalid or
    too deeply nested JSON, a field of the wrong type, a missing image) is an :class:`polyjax.InputError` naming
    it, raised before the fit."""
    path = Path(path)
    spec = _read_spec(path)
    entries = _field(spec, "images", str(path), required=True)
    if not isinstance(entries, list) or not entries:
        raise InputError(f"{path}: 'images' must be a non-empty list")
    images = []
    for i, e in enumerate(entries):
        f = _file(e, f"{path}: images[{i}]", path, f"images[{i}].file")
        if not f.exists():
            raise InputError(f"{path}: images[{i}]: file {f} not found")
        images.append(read_exr(f))
    camera = _camera(spec, path, images)
    objects = _objects(spec, path)
    scenes = [Scene(camera, objects, _lights(e, path, i)) for i, e in enumerate(entries)]
    target = spec.get("target", 0)
    if isinstance(target, bool) or not isinstance(target, int):
        raise InputError(f"{path}: target: expected an integer, found {target!r}")
    return scenes, images, target


def run_fit_images(args) -> int:
    """Run ``polyjax fit-images`` from parsed arguments; returns the exit status."""
    if args.example is not None:
        path = write_example_scene(check_output_dir(args.example, "--example"))
        print(f"example written to {path}; fit it with: polyjax fit-images {path}")
        return 0
    if args.scene is None:
        raise InputError("scene: expected a JSON scene file (or --example DIR to write one to start from)")
    spec = spec_from_args(args)
    if args.save:
        check_model_file(args.save, "--save")  # before any work
    scenes, images, target = load_scene_json(args.scene)
    model = pj.fit_polynomial_to_images(scenes, images, spec=spec, target=target, saturation=args.saturation,
                                        cutoff_deg=args.cutoff, spp=args.spp, weighting="radiance")
    status = [pj.RESULTS(int(s)).name for s in np.asarray(model.status)]
    out = {
        "images": len(images), "pixels_used": int(np.asarray(model.n_used)[0]), "variables": spec.variables,
        "degree": spec.degree, "spec": spec.to_dict(), "rms_residual_rgb": np.asarray(model.l2).tolist(),
        "status_rgb": status,
        "condition": float(np.asarray(model.condition)[0]), "coefficients_rgb": np.asarray(model.coefficients).tolist(),
    }
    if args.save:
        pj.save_model(args.save, model)
        out["saved"] = str(args.save)
    if args.json:
        print(strict_json(out))
    else:
        print(f"fit-images: {out['images']} images, {out['pixels_used']} pixels used, {spec.variables} p={spec.degree}")
        print("  RMS radiance residual (R, G, B): " + ", ".join(f"{x:.4g}" for x in out["rms_residual_rgb"]))
        print(f"  status: {', '.join(status)}; condition number {out['condition']:.3g}")
        if args.save:
            print(f"  model written to {args.save}")
    return 0 if all(s == "OK" for s in status) else 1


def add_parser(sub, common) -> None:
    """The ``fit-images`` command's parser."""
    add_fit_images_parser(sub, parents=[common])
