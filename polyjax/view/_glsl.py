r"""The page's BRDF functions in GLSL ES 3.00 (WebGL2): ``vec3 brdf_<i>(vec3 u, vec3 v)`` per item and one
dispatcher ``vec3 brdf(int k, vec3 u, vec3 v)``.

A ``"program"`` item's body is :meth:`polyjax.export._expr.Program.glsl_body`, the text the GLSL export prints
(:func:`polyjax.export.glsl`), so the page and the export are one source. A ``"table"`` item reads its 3D texture
with ``merl_lookup`` (``viewer.js``): Rusinkiewicz angles of ``(u, v)`` (:func:`polyjax.data._merl.
directions_to_rusinkiewicz`), continuous MERL indices ``sqrt(theta_h / (pi/2)) N_h``, ``theta_d / (pi/2) N_d``,
``phi_d / pi N_p`` (``phi_d`` folded into ``[0, pi)`` by reciprocity; the texture repeats along ``phi_d``),
trilinear between bin centres; a table of a BRDF that is not reciprocal has ``phi_d`` over ``[0, 2 pi)``
(``polyjax.export._merl.whole_turn``), read with the period ``2 pi``. ``"points"`` items have no function
(the dispatcher returns 0 for them).
"""

from __future__ import annotations

from ._items import ViewItem


def _program_function(i: int, item: ViewItem) -> str:
    return (f"vec3 brdf_{i}(vec3 u, vec3 v) {{\n"
            "    float ux = u.x; float uy = u.y; float uz = u.z;\n"
            "    float vx = v.x; float vy = v.y; float vz = v.z;\n"
            f"{item.program.glsl_body()}\n"
            "    return vec3(out_r, out_g, out_b);\n}\n")


def _table_function(i: int, item: ViewItem) -> str:
    nh, nd, npd = item.table.shape[:3]
    period = "PI" if item.reciprocal else "2.0 * PI"
    return (f"uniform highp sampler3D table_{i};\n"
            f"vec3 brdf_{i}(vec3 u, vec3 v) {{\n"
            f"    return merl_lookup(table_{i}, vec3({nh}.0, {nd}.0, {npd}.0), u, v, {period});\n}}\n")


def brdf_functions(items: list[ViewItem]) -> str:
    """GLSL of every item's function and the dispatcher ``brdf(k, u, v)`` (``k`` the item's index)."""
    parts, cases = [], []
    for i, item in enumerate(items):
        if item.kind == "program":
            parts.append(_program_function(i, item))
        elif item.kind == "table":
            parts.append(_table_function(i, item))
        else:
            continue
        cases.append(f"    if (k == {i}) return brdf_{i}(u, v);")
    body = "\n".join(cases)
    parts.append(f"vec3 brdf(int k, vec3 u, vec3 v) {{\n{body}\n    return vec3(0.0);\n}}\n")
    return "\n".join(parts)
