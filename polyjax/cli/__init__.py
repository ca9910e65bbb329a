"""The ``polyjax`` command line: :func:`main` (the console script and ``python -m polyjax``) and its parser,
:func:`build_parser`; :func:`load_scene_json`, the reader of ``polyjax fit-images``'s scene files (imported on first
use, as it loads :mod:`polyjax.render`)."""

from ._main import build_parser, main

__all__ = ["build_parser", "load_scene_json", "main"]


def __getattr__(name: str):
    if name == "load_scene_json":  # the scene reader imports polyjax.render: loaded on first use
        from ._fit_images import load_scene_json

        return load_scene_json
    raise AttributeError(f"module 'polyjax.cli' has no attribute {name!r}")
