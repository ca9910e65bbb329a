"""``polyjax export MODEL --to mitsuba|brdf-explorer|glsl|merl|rgl-bsdf --out PATH``: a saved model in another
renderer."""

from __future__ import annotations

import argparse
import os
import sys
import warnings
from pathlib import Path

import polyjax as pj

from .._config import check_output_file
from .._errors import InputError
from .._files import write_bytes_atomically
from ..export._expr import program
from ..export._glsl import brdf_explorer, glsl
from ..export._merl import NotReciprocalWarning, merl_binary
from ..export._mitsuba_name import check_plugin_name
from ..export._rgl import is_rgl_source, rgl_to_merl
from ..export._rgl_bsdf import NotSymmetricWarning, rgl_bsdf
from ..render._brdf import rgb_brdf
from ._export_standard import TARGETS, add_standard_arguments, run_standard_export

#: the suffixes ``--out`` may end in for each target written here, the default first (the standard targets'
#: writers check their own)
SUFFIXES = {"mitsuba": (".py",), "brdf-explorer": (".brdf",), "glsl": (".glsl", ".frag"), "merl": (".binary",),
            "rgl-bsdf": (".bsdf",)}
#: target -> the default suffix of its output
FORMATS = {to: suffixes[0] for to, suffixes in SUFFIXES.items()}

#: the Mitsuba plugin file: user strings (the model's path, its lane, the plugin name) appear only as ``repr``
#: literals in the three assignments below the docstring, never in the docstring or a comment
_MITSUBA_SCRIPT = '''"""Mitsuba 3 BSDF plugin of a polyjax model (written by `polyjax export --to mitsuba`).

    import mitsuba as mi
    mi.set_variant("llvm_ad_rgb")        # or "scalar_rgb"
    import <this file's name>
    <this file's name>.register()        # then {{"type": NAME}} in mi.load_dict / scene files
"""

MODEL = {model}
INDEX = {index}
NAME = {name}


def model_path():
    """MODEL, relative to this file's folder unless absolute: the plugin and its model move together."""
    import os

    return MODEL if os.path.isabs(MODEL) else os.path.join(os.path.dirname(os.path.abspath(__file__)), MODEL)


def register(name=NAME):
    import jax

    jax.config.update("jax_enable_x64", True)
    import polyjax as pj

    model = pj.load_model(model_path())
    if INDEX is not None:
        model = model[INDEX]
    return pj.export.register_mitsuba_bsdf(model, name)
'''


def add_export_parser(sub, parents=()) -> argparse.ArgumentParser:
    p = sub.add_parser("export", parents=list(parents),
                       help="write a saved model for Mitsuba 3, BRDF Explorer, GLSL or MERL tools")
    p.add_argument("model", help="a model written by `polyjax fit --save` (.npz or .json)")
    p.add_argument("--to", required=True, choices=sorted(FORMATS) + sorted(TARGETS), help="target format")
    p.add_argument("--out", default=None, help="output file (default: the model's name with the format's suffix)")
    p.add_argument("--index", action="append", default=None,
                   help="lane of a batched model (e.g. the material, or degree then material) when it holds more "
                   "than one BRDF: one integer per leading batch axis, comma-separated or repeated (--index 1,0 "
                   "or --index 1 --index 0)")
    p.add_argument("--name", default="polyjax", help="Mitsuba plugin name (--to mitsuba)")
    add_standard_arguments(p)  # --to gltf, mitsuba-xml: a standard material fitted to a model or data set
    return p


def _lane_index(texts, batch_shape) -> tuple[int, ...] | None:
    """``--index`` values (each ``"1"`` or ``"1,0"``) -> one integer per leading batch axis, checked against
    ``batch_shape``; None when not given."""
    if not texts:
        return None
    try:
        index = tuple(int(t) for text in texts for t in str(text).split(",") if t.strip())
    except ValueError:
        index = ()
    if not index:
        raise InputError(f"--index: expected integers (e.g. --index 1,0 or --index 1 --index 0), found {texts}")
    bs = tuple(batch_shape)
    if len(index) > len(bs) or not all(-n <= i < n for i, n in zip(index, bs)):
        raise InputError(f"--index: expected at most one lane per axis of the model's batch shape {bs} (each in "
                         f"[0, size)), found {','.join(map(str, index))}")
    return index


def _check_one_brdf(model, index) -> None:
    """Refuse, naming the command line's ``--index``, a model that still holds several BRDFs."""
    bs = tuple(model.batch_shape)
    if bs not in ((), (1,), (3,)):
        given = f" after --index {','.join(map(str, index))}" if index else ""
        raise InputError(f"--index: the model holds more than one BRDF (batch shape {bs}{given}): select one lane "
                         f"per leading axis, e.g. --index {','.join('0' * (len(bs) - 1 or 1))}")


def run_export(args) -> int:
    """Run ``polyjax export``: the output path is checked before the model is read; returns the exit status."""
    if is_rgl_source(args.model):
        return _run_rgl_export(args)

    if args.to in TARGETS:
        return run_standard_export(args)
    src = Path(args.model)
    out = _output_file(args, src.with_suffix(FORMATS[args.to]))
    if args.to == "mitsuba":
        check_plugin_name(args.name, "--name")
    model = pj.load_model(src)
    index = _lane_index(args.index, model.batch_shape)
    if index is not None:
        model = model[index]
    _check_one_brdf(model, index)
    if args.to == "glsl":
        write_bytes_atomically(out, glsl(model).encode())
    elif args.to == "brdf-explorer":
        brdf_explorer(model, out)
    elif args.to == "merl":
        _warning_lines(lambda: merl_binary(model, out), NotReciprocalWarning)
    elif args.to == "rgl-bsdf":
        _warning_lines(lambda: rgl_bsdf(model, out, description=f"polyjax export of {src.name}"), NotSymmetricWarning)
    else:
        if isinstance(model, pj.PolynomialBRDF):
            program(model)  # fail now, not inside Mitsuba, on models that cannot be exported
        rgb_brdf(model)
        text = _MITSUBA_SCRIPT.format(model=repr(_relative_to(src, out.parent)), index=repr(index),
                                      name=repr(args.name))
        write_bytes_atomically(out, text.encode())
    print(f"wrote {out} ({args.to})")
    return 0


def _warning_lines(write, category) -> None:
    """``write()``, its warnings of ``category`` printed as one line on stderr, as the command's other messages; any
    other warning as it came."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", category)
        write()
    for w in caught:
        if issubclass(w.category, category):
            print(f"polyjax: warning: {w.message}", file=sys.stderr)
        else:
            warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)


def _output_file(args, default: Path) -> Path:
    """``--out`` (or ``default``) checked before any work: its suffix one of the target's (:data:`SUFFIXES`), then
    :func:`check_output_file`'s checks."""
    if args.out and Path(args.out).suffix.lower() not in SUFFIXES[args.to]:
        raise InputError(f"--out: expected a file name ending in {' or '.join(SUFFIXES[args.to])} for --to "
                         f"{args.to}, found {args.out!r}")
    return check_output_file(Path(args.out) if args.out else default, "--out")


def _relative_to(path: Path, folder: Path) -> str:
    """``path`` relative to ``folder`` (``..`` allowed), absolute where there is no relative path (another
    drive)."""
    try:
        return os.path.relpath(path.resolve(), folder.resolve())
    except ValueError:
        return str(path.resolve())


def _run_rgl_export(args) -> int:
    """``polyjax export <file.bsdf or rgl:spec> --to merl``: an RGL-EPFL measured BSDF as a MERL ``.binary``;
    ``--to gltf|mitsuba-xml|openpbr|usd``: the standard material fitted to it, as to any data set."""
    if args.to in TARGETS:
        return run_standard_export(args)
    if args.to != "merl":
        raise pj.InputError(f"--to: an RGL-EPFL file converts to 'merl', {', '.join(sorted(TARGETS))}, found "
                            f"{args.to!r}")
    name = args.model[4:] if args.model.lower().startswith("rgl:") else args.model
    out = _output_file(args, Path(Path(name).stem + FORMATS["merl"]))
    rgl_to_merl(name, out, root=getattr(args, "data_root", None))
    print(f"wrote {out} (merl, from the RGL-EPFL file {name})")
    return 0


def add_parser(sub, common) -> None:
    """The ``export`` command's parser."""
    add_export_parser(sub, parents=[common]).set_defaults(func=run_export)
