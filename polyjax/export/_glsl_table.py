r"""GLSL of a tabulated BRDF: any model without an expression program (a ``baselines.BaselineFit``, a
``TabulatedBRDF``, a closure) as ``vec3 BRDF(vec3 L, vec3 V, vec3 N, vec3 X, vec3 Y)`` over a table.

The table holds ``max(f, 0)`` at the nodes of a coarse MERL grid (:func:`polyjax.export.tabulate_merl` at
``resolution = (N_h, N_d, N_p)``, default ``(16, 16, 32)``: node ``(i, j, k)`` at ``theta_h = (i / N_h)^2 pi / 2``,
``theta_d = j / N_d pi / 2``, ``phi_d = k / N_p pi``; a BRDF that is not reciprocal gets ``2 N_p`` nodes over
the whole turn, ``phi_d = k / N_p pi`` for ``k < 2 N_p``, :func:`polyjax.export._merl.whole_turn`: the shader's
``TURN`` is then 2), and the shader interpolates it trilinearly in the bin
coordinates exactly as the Mitsuba plugin does for such models (:mod:`polyjax.export._mitsuba`): ``sqrt`` of
``theta_h`` and ``theta_d`` clamped to the grid, ``phi_d`` periodic, nodes with a direction below the horizon left
out of the weights. :func:`tabulated_numpy` is the same interpolation in numpy (what the tests compare with the
model). An approximation at the table's resolution; the table is a ``const float`` array (GLSL 1.20 and later).
"""

from __future__ import annotations

import re

import numpy as np

from .._errors import InputError
from ._merl import tabulate_both_orders

#: the default table resolution (N_h, N_d, N_p): 8,192 nodes, 32,768 floats
RESOLUTION = (16, 16, 32)
#: what a generated file's comment may hold of a name that came from outside (a file's, a model's): anything else
#: (a newline, a quote, ``*/``) becomes ``?``, so no name can end the comment and add code
_COMMENT_SAFE = re.compile(r"[^A-Za-z0-9_ .,=()\[\]+-]")


def comment_text(text) -> str:
    """``str(text)`` with every character that could end a comment replaced by ``?`` (:data:`_COMMENT_SAFE`)."""
    return _COMMENT_SAFE.sub("?", str(text))


def check_function_name(name) -> str:
    """``name`` when it is a GLSL identifier (letters, digits and ``_``, not starting with a digit).

    Raises:
        InputError: naming the name found.
    """
    if not (isinstance(name, str) and name.isascii() and name.isidentifier()):
        raise InputError(f"name: expected a GLSL function name (letters, digits and _), found {name!r}")
    return name

_BODY = """
    vec3 u = normalize(vec3(dot(L, X), dot(L, Y), dot(L, N)));
    vec3 v = normalize(vec3(dot(V, X), dot(V, Y), dot(V, N)));
    if (u.z <= 0.0 || v.z <= 0.0) return vec3(0.0);
    const float PI = 3.14159265358979;
    vec3 h = normalize(u + v);
    float th = acos(clamp(h.z, -1.0, 1.0));
    float rh = length(h.xy);
    float cp = rh > 1e-12 ? h.x / rh : 1.0;
    float sp = rh > 1e-12 ? h.y / rh : 0.0;
    float x = cp * u.x + sp * u.y;
    float y = -sp * u.x + cp * u.y;
    float dx = x * cos(th) - u.z * sin(th);
    float dz = x * sin(th) + u.z * cos(th);
    float td = atan(sqrt(dx * dx + y * y), dz);
    float pd = atan(y == 0.0 ? 0.0 : y, dx);  // +0.0 for -0.0: a pair turned by pi reads pi, not -pi
    if (pd < 0.0) pd += TURN * PI;
    float ci = sqrt(max(th, 0.0) / (PI / 2.0)) * float(NH);
    float cj = clamp(td, 0.0, PI / 2.0) / (PI / 2.0) * float(ND);
    float ck = clamp(pd, 0.0, TURN * PI) / (TURN * PI) * float(NP);
    int i0 = int(clamp(floor(ci), 0.0, float(NH - 2)));
    float wi = clamp(ci - float(i0), 0.0, 1.0);
    int j0 = int(clamp(floor(cj), 0.0, float(ND - 2)));
    float wj = clamp(cj - float(j0), 0.0, 1.0);
    int k0 = int(floor(ck));
    float wk = ck - float(k0);
    if (k0 >= NP) k0 -= NP;
    int k1 = k0 + 1 >= NP ? k0 + 1 - NP : k0 + 1;
    vec4 acc = vec4(0.0);
    for (int a = 0; a < 2; a++) {
        for (int b = 0; b < 2; b++) {
            for (int c = 0; c < 2; c++) {
                int idx = (c == 0 ? k0 : k1) + NP * ((j0 + b) + ND * (i0 + a));
                float w = (a == 0 ? 1.0 - wi : wi) * (b == 0 ? 1.0 - wj : wj) * (c == 0 ? 1.0 - wk : wk);
                acc += w * vec4(TABLE[idx], TABLE[NN + idx], TABLE[2 * NN + idx], TABLE[3 * NN + idx]);
            }
        }
    }
    return acc.w > 0.0 ? acc.xyz / acc.w : vec3(0.0);
"""


def table(model, resolution=RESOLUTION) -> tuple[np.ndarray, int]:
    """``((4, N), turn)``: ``max(f, 0)`` per channel at the nodes (file order), then 1 where both directions of the
    node are above the horizon (0 elsewhere, the values there 0); ``turn`` 2 for a table over the whole turn of
    ``phi_d`` (``N = 2 N_h N_d N_p``, a BRDF that is not reciprocal), else 1."""
    vals, above, turn = tabulate_both_orders(model, tuple(resolution))
    vals = np.where(above[None], np.maximum(vals, 0.0), 0.0).reshape(3, -1)
    return np.concatenate([vals, above.reshape(1, -1).astype(np.float64)]), 2 if turn else 1


def tabulated_glsl(model, name: str = "BRDF", resolution=RESOLUTION) -> str:
    """GLSL source of ``vec3 name(vec3 L, vec3 V, vec3 N, vec3 X, vec3 Y)`` interpolating ``model``'s table."""
    check_function_name(name)
    nh, nd, npd = (int(r) for r in resolution)
    t, turn = table(model, resolution)
    npd *= turn
    data = ",".join(f"{x:.9g}" for x in t.ravel())
    header = (f"// polyjax tabulated BRDF ({comment_text(type(model).__name__)} "
              f"{comment_text(getattr(model, 'name', ''))}): max(f, 0) at "
              f"{nh}x{nd}x{npd} Rusinkiewicz nodes, trilinear"
              + ("; not reciprocal: phi_d over the whole turn" if turn == 2 else ""))
    return (f"{header}\nconst int NH = {nh};\nconst int ND = {nd};\nconst int NP = {npd};\n"
            f"const float TURN = {turn}.0;\n"
            f"const int NN = {nh * nd * npd};\nconst float TABLE[{t.size}] = float[{t.size}]({data});\n"
            f"vec3 {name}(vec3 L, vec3 V, vec3 N, vec3 X, vec3 Y)\n{{{_BODY}}}\n")


def tabulated_numpy(model, resolution=RESOLUTION):
    """``f(u, v) -> (n, 3)``: the interpolation of :func:`tabulated_glsl` in numpy (float64), local frame."""
    nh, nd, npd = (int(r) for r in resolution)
    t, turn = table(model, resolution)
    npd *= turn

    def f(u, v):
        u = np.asarray(u, np.float64) / np.linalg.norm(u, axis=-1, keepdims=True)
        v = np.asarray(v, np.float64) / np.linalg.norm(v, axis=-1, keepdims=True)
        h = (u + v) / np.linalg.norm(u + v, axis=-1, keepdims=True)
        th = np.arccos(np.clip(h[:, 2], -1, 1))
        rh = np.hypot(h[:, 0], h[:, 1])
        ok = rh > 1e-12
        cp = np.where(ok, h[:, 0] / np.where(ok, rh, 1), 1.0)
        sp = np.where(ok, h[:, 1] / np.where(ok, rh, 1), 0.0)
        x, y = cp * u[:, 0] + sp * u[:, 1], -sp * u[:, 0] + cp * u[:, 1]
        dx, dz = x * np.cos(th) - u[:, 2] * np.sin(th), x * np.sin(th) + u[:, 2] * np.cos(th)
        td, pd = np.arctan2(np.hypot(dx, y), dz), np.arctan2(np.where(y == 0.0, 0.0, y), dx)
        pd = np.where(pd < 0, pd + turn * np.pi, pd)
        ci = np.sqrt(np.maximum(th, 0) / (np.pi / 2)) * nh
        cj = np.clip(td, 0, np.pi / 2) / (np.pi / 2) * nd
        ck = np.clip(pd, 0, turn * np.pi) / (turn * np.pi) * npd
        i0 = np.clip(np.floor(ci), 0, nh - 2).astype(int)
        j0 = np.clip(np.floor(cj), 0, nd - 2).astype(int)
        wi, wj = np.clip(ci - i0, 0, 1), np.clip(cj - j0, 0, 1)
        k0 = np.floor(ck).astype(int)
        wk = ck - k0
        k0 = np.where(k0 >= npd, k0 - npd, k0)
        k1 = np.where(k0 + 1 >= npd, k0 + 1 - npd, k0 + 1)
        acc = np.zeros((4, u.shape[0]))
        for a, wa in ((0, 1 - wi), (1, wi)):
            for b, wb in ((0, 1 - wj), (1, wj)):
                for k, wc in ((k0, 1 - wk), (k1, wk)):
                    acc += wa * wb * wc * t[:, k + npd * ((j0 + b) + nd * (i0 + a))]
        above = (u[:, 2] > 0) & (v[:, 2] > 0) & (acc[3] > 0)
        return np.where(above[:, None], (acc[:3] / np.where(acc[3] > 0, acc[3], 1)).T, 0.0)

    return f


__all__ = ["RESOLUTION", "table", "tabulated_glsl", "tabulated_numpy"]
