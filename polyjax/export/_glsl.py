"""GLSL export: ``vec3 BRDF(vec3 L, vec3 V, vec3 N, vec3 X, vec3 Y)`` and Disney BRDF Explorer ``.brdf`` files.

The function takes world-space light ``L`` and view ``V`` directions and the shading frame (normal ``N``,
tangent ``X``, bitangent ``Y``), forms the local directions ``u = (L.X, L.Y, L.N)`` and ``v = (V.X, V.Y, V.N)``
and evaluates the model there (the program of :mod:`polyjax.export._expr`, the same arithmetic as the numpy
version the tests compare with the model). It returns linear RGB BRDF values in 1/sr (the polynomial is not
clamped: it can be negative where the fit is). Not differentiable (text output).
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from .._files import check_output_path, write_bytes_atomically
from .._model import PolynomialBRDF
from ..data._nbrdf import NeuralBRDF
from ._expr import program
from ._glsl_table import check_function_name, comment_text, tabulated_glsl, tabulated_numpy

_HEADER = "// polyjax {what}: variables={variables}, basis={basis}, degree={degree}, interactions={interactions}"


def glsl(model, name: str = "BRDF") -> str:
    """GLSL source of ``vec3 name(vec3 L, vec3 V, vec3 N, vec3 X, vec3 Y)`` evaluating ``model``.

    Args:
        model: a :class:`polyjax.PolynomialBRDF` of batch shape ``()``, ``(1,)`` or ``(3,)``, or a
            ``polyjax.data.NeuralBRDF`` (its network written out); any other BRDF (e.g. a ``baselines.BaselineFit``
            of one lane or three channels) is tabulated (:mod:`polyjax.export._glsl_table`).
        name: the function's name (BRDF Explorer calls ``BRDF``).

    Returns:
        The source (GLSL 1.20 and later: scalar ``float`` arithmetic, ``sqrt``, ``max``).
    """
    check_function_name(name)
    if not _has_program(model):  # baseline fits and other BRDFs: a table (polyjax/export/_glsl_table.py)

        return tabulated_glsl(model, name)
    prog = program(model)
    if hasattr(model, "variables"):
        header = comment_text(_HEADER.format(what="polynomial BRDF", variables=model.variables, basis=model.basis,
                                             degree=[int(d) for d in np.asarray(model.degree).ravel()],
                                             interactions=model.interactions)[3:])
        header = f"// {header}"
    else:
        header = f"// polyjax neural BRDF {comment_text(getattr(model, 'name', ''))} (Sztrajman et al. 2021)"
    return (
        f"{header}\n"
        f"vec3 {name}(vec3 L, vec3 V, vec3 N, vec3 X, vec3 Y)\n{{\n"
        "    float ux = dot(L, X); float uy = dot(L, Y); float uz = dot(L, N);\n"
        "    float vx = dot(V, X); float vy = dot(V, Y); float vz = dot(V, N);\n"
        f"{prog.glsl_body()}\n"
        "    return vec3(out_r, out_g, out_b);\n}\n"
    )


def _has_program(model) -> bool:
    """Whether ``model`` has an expression program (a polynomial model or a neural BRDF), else it is tabulated."""
    return isinstance(model, (PolynomialBRDF, NeuralBRDF))


def brdf_explorer(model, path: str | os.PathLike) -> Path:
    """Write a Disney BRDF Explorer ``.brdf`` file (its ``analytic`` format) for ``model``.

    The file holds an empty parameter block and the GLSL of :func:`glsl` between ``::begin shader`` and
    ``::end shader``. Returns the path written.
    """
    path = check_output_path(path, "path")
    src = glsl(model)
    text = ("analytic\n\n# exported by polyjax\n\n::begin parameters\n::end parameters\n\n"
            f"::begin shader\n\n{src}\n::end shader\n")
    return write_bytes_atomically(path, text.encode())


def numpy_function(model):
    """``f(u, v) -> (..., 3)`` in numpy, from the same program as :func:`glsl` (for checking exports); for a model
    :func:`glsl` tabulates, the same table and interpolation (:func:`polyjax.export._glsl_table.tabulated_numpy`,
    directions ``(n, 3)``)."""
    if not _has_program(model):
        return tabulated_numpy(model)
    fn = program(model).python_function("numpy")

    def f(u, v):
        u, v = np.broadcast_arrays(np.asarray(u, np.float64), np.asarray(v, np.float64))
        with np.errstate(divide="ignore", invalid="ignore"):
            out = fn(*np.moveaxis(u, -1, 0), *np.moveaxis(v, -1, 0))
        return np.stack([np.broadcast_to(o, u.shape[:-1]) for o in out], axis=-1)

    return f


__all__ = ["brdf_explorer", "glsl", "numpy_function"]
