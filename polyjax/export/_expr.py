r"""One expression builder for every exporter: a straight-line program of scalar expressions, printed as GLSL,
numpy or Dr.Jit (Mitsuba 3) code.

A :class:`Program` is a list of assignments ``name = expression`` over the inputs ``ux, uy, uz`` (light) and
``vx, vy, vz`` (view), local frame with normal ``+z``, and three outputs ``out_r, out_g, out_b``. Expressions are
nested tuples (:func:`add`, :func:`mul`, ...), so every dialect prints the same arithmetic in the same order:
the numpy print, evaluated in float64, is what the tests compare with the model; the GLSL print is compiled by
``glslangValidator``; the Dr.Jit print runs inside Mitsuba.

:func:`neural_program` builds that of a ``NeuralBRDF`` (its MLP written out). :func:`polynomial_program` builds
the program of a :class:`polyjax.PolynomialBRDF` (paper equation (3), or (2) with
interactions): normalise ``u`` and ``v``; the explanatory variables ``X`` of its variable set; per channel the
principal components ``t_j = (sum_i (X_i - mean_i) R_ij - centre_j) / halfwidth_j`` (``t_j = 0`` for an infinite
half-width; ``max(min(t_j, 1), -1)`` for a model with ``clamp``); the basis ``B_e = prod_j P_{e_j}(t_j)`` (Legendre
by the three-term recurrence, or monomials); ``f = sum_e beta_e B_e`` (``exp(f) - eps`` for the log link); 0 unless
``u_z > 0`` and ``v_z > 0``.
"""

from __future__ import annotations

import numpy as np

from .._basis import exponents
from .._errors import InputError
from .._model import PolynomialBRDF
from ..data._nbrdf import NeuralBRDF
from ..render._brdf import transported

INPUTS = ("ux", "uy", "uz", "vx", "vy", "vz")
OUTPUTS = ("out_r", "out_g", "out_b")


def const(x: float):
    return ("const", float(x))


def var(name: str):
    return ("var", name)


def add(*xs):
    xs = [x for x in xs if x != ("const", 0.0)]
    if not xs:
        return const(0.0)
    out = xs[0]
    for x in xs[1:]:
        out = ("+", out, x)
    return out


def sub(a, b):
    return ("-", a, b)


def mul(*xs):
    out = xs[0]
    for x in xs[1:]:
        out = ("*", out, x)
    return out


def div(a, b):
    return ("/", a, b)


def call(fn: str, *args):
    """``fn`` in ``sqrt``, ``max`` and ``min`` (two arguments) or ``exp``."""
    return ("call", fn, *args)


def transported_expression(f):
    """``max(f, 0)`` as an expression: :func:`polyjax.render._brdf.transported` with this program's ``max``."""
    return transported(f, maximum=lambda a, b: call("max", a, b), zero=const(0.0))


def where_positive(a, b, value):
    """``value`` where ``a > 0`` and ``b > 0``, else 0."""
    return ("where", a, b, value)


def select_gt(a, b, x, y):
    """``x`` where ``a > b``, else ``y``."""
    return ("select", a, b, x, y)


class Program:
    """A straight-line program: ``assign`` adds ``name = expression`` and returns ``var(name)``."""

    def __init__(self):
        self.lines: list[tuple[str, tuple]] = []
        self._n = 0

    def assign(self, expr, prefix: str = "t") -> tuple:
        if expr[0] in ("var", "const"):
            return expr
        name = f"{prefix}{self._n}"
        self._n += 1
        self.lines.append((name, expr))
        return var(name)

    def output(self, values) -> None:
        for name, e in zip(OUTPUTS, values):
            self.lines.append((name, e))

    # ----------------------------------------------------------------------- printing

    def _print(self, e, d: str) -> str:
        kind = e[0]
        if kind == "const":
            x = e[1]
            if d == "glsl":
                s = f"{x:.9g}"
                if "e" not in s and "." not in s and "n" not in s:
                    s += ".0"
                return s if x >= 0 else f"({s})"
            return repr(x) if x >= 0 else f"({x!r})"
        if kind == "var":
            return e[1]
        if kind in "+-*/":
            return f"({self._print(e[1], d)} {kind} {self._print(e[2], d)})"
        if kind == "call":
            fn, args = e[1], [self._print(a, d) for a in e[2:]]
            name = {"glsl": {"sqrt": "sqrt", "max": "max", "min": "min", "exp": "exp"},
                    "numpy": {"sqrt": "np.sqrt", "max": "np.maximum", "min": "np.minimum", "exp": "np.exp"},
                    "drjit": {"sqrt": "dr.sqrt", "max": "dr.maximum", "min": "dr.minimum", "exp": "dr.exp"}}[d][fn]
            return f"{name}({', '.join(args)})"
        if kind == "where":
            a, b, value = (self._print(x, d) for x in e[1:])
            if d == "glsl":
                return f"((({a}) > 0.0 && ({b}) > 0.0) ? ({value}) : 0.0)"
            if d == "numpy":
                return f"np.where(({a} > 0) & ({b} > 0), {value}, 0.0)"
            return f"dr.select(({a} > 0) & ({b} > 0), {value}, 0.0)"
        if kind == "select":
            a, b, x, y = (self._print(z, d) for z in e[1:])
            if d == "glsl":
                return f"(({a} > {b}) ? ({x}) : ({y}))"
            fn = "np.where" if d == "numpy" else "dr.select"
            return f"{fn}({a} > {b}, {x}, {y})"
        raise ValueError(f"unknown expression kind {kind!r}")

    def glsl_body(self, indent: str = "    ") -> str:
        return "\n".join(f"{indent}float {n} = {self._print(e, 'glsl')};" for n, e in self.lines)

    def python_source(self, dialect: str, name: str = "brdf") -> str:
        """Source of ``def name(ux, uy, uz, vx, vy, vz): ... return out_r, out_g, out_b`` (numpy or drjit)."""
        body = "\n".join(f"    {n} = {self._print(e, dialect)}" for n, e in self.lines)
        return f"def {name}({', '.join(INPUTS)}):\n{body}\n    return {', '.join(OUTPUTS)}\n"

    def python_function(self, dialect: str):
        """The compiled Python function of :meth:`python_source` (``np`` or ``dr`` bound in its globals)."""
        if dialect == "numpy":
            env = {"np": np}
        else:
            import drjit as dr  # optional (the "mitsuba" extra): imported where used

            env = {"dr": dr}
        code = compile(self.python_source(dialect), f"<polyjax {dialect} export>", "exec")
        exec(code, env)  # noqa: S102 - the program printed above, nothing from outside
        return env["brdf"]


# --------------------------------------------------------------------------- the polynomial model


def _variables(prog: Program, name: str, u, v):
    ux, uy, uz = u
    vx, vy, vz = v
    if name == "lafortune":
        return [prog.assign(add(mul(ux, vx), mul(uy, vy))), prog.assign(mul(uz, vz))]
    if name == "lafortune-anisotropic":
        return [prog.assign(mul(ux, vx)), prog.assign(mul(uy, vy)), prog.assign(mul(uz, vz))]
    if name in ("ward", "ashikhmin-shirley"):
        hx, hy, hz = (prog.assign(add(a, b)) for a, b in zip(u, v))
        inv = prog.assign(div(const(1.0), call("sqrt", add(mul(hx, hx), mul(hy, hy), mul(hz, hz)))))
        nh = prog.assign(mul(hz, inv))
        if name == "ward":
            return [nh, prog.assign(mul(uz, vz))]
        vh = prog.assign(mul(add(mul(vx, hx), mul(vy, hy), mul(vz, hz)), inv))
        return [nh, vh, prog.assign(call("max", uz, vz))]
    raise InputError(
        f"model: variables {name!r} cannot be exported (built-in sets only: lafortune, lafortune-anisotropic, "
        "ward, ashikhmin-shirley)"
    )


def _unit(prog: Program, names):
    a, b, c = (var(n) for n in names)
    inv = prog.assign(div(const(1.0), call("sqrt", add(mul(a, a), mul(b, b), mul(c, c)))))
    return [prog.assign(mul(x, inv)) for x in (a, b, c)]


def _channel(prog: Program, model: PolynomialBRDF, lane: int, x):
    k, p = model.k, model.max_degree
    coef = np.asarray(model.coefficients, np.float64).reshape(-1, model.coefficients.shape[-1])[lane]
    mean = np.asarray(model.mean, np.float64).reshape(-1, k)[lane]
    rot = np.asarray(model.rotation, np.float64).reshape(-1, k, k)[lane]
    centre = np.asarray(model.centre, np.float64).reshape(-1, k)[lane]
    hw = np.asarray(model.halfwidth, np.float64).reshape(-1, k)[lane]
    dx = [prog.assign(sub(x[i], const(mean[i]))) for i in range(k)]
    ts = []
    for j in range(k):
        if not np.isfinite(hw[j]):
            ts.append(const(0.0))
            continue
        z = add(*[mul(dx[i], const(rot[i, j])) for i in range(k)])
        t = prog.assign(div(sub(z, const(centre[j])), const(hw[j])))
        if model.clamp:  # the nearest point of the fitted box
            t = prog.assign(call("max", call("min", t, const(1.0)), const(-1.0)))
        ts.append(t)
    powers = []  # powers[j][d] = P_d(t_j) or t_j^d
    for t in ts:
        col = [const(1.0)]
        if p >= 1:
            col.append(t)
        for d in range(2, p + 1):
            if model.basis == "monomial":
                col.append(prog.assign(mul(col[-1], t)))
            else:
                col.append(prog.assign(div(sub(mul(const(2 * d - 1), t, col[-1]), mul(const(d - 1), col[-2])),
                                           const(d))))
        powers.append(col)
    terms = []
    for e, c in zip(exponents(k, p, model.interactions), coef):
        if c == 0.0:
            continue
        factors = [powers[j][e[j]] for j in range(k) if e[j] > 0]
        terms.append(mul(const(c), *factors) if factors else const(c))
    f = add(*terms) if terms else const(0.0)
    if model.link == "log":  # f = exp(min(poly, log_top)) - eps
        f = prog.assign(f)
        if model.log_top is not None:
            top = float(np.asarray(model.log_top, np.float64).reshape(-1)[lane])
            if np.isfinite(top):  # inf: a lane without samples, no bound
                f = prog.assign(call("min", f, const(top)))
        f = sub(call("exp", f), const(model.eps))
    return prog.assign(f, prefix="f")


def neural_program(model) -> Program:
    """The :class:`Program` of a ``polyjax.data.NeuralBRDF`` (Sztrajman et al. 2021): network inputs
    ``(h, d)`` from the normalised directions (``phi_h`` rotated to 0; at the pole ``theta_h = 0``), two ReLU
    layers, ``exp(z) - 1``, negative outputs clamped to 0, 0 unless both directions are above the horizon."""
    prog = Program()
    ux, uy, uz = _unit(prog, INPUTS[:3])
    vx, vy, vz = _unit(prog, INPUTS[3:])
    sx, sy, sz = (prog.assign(add(a, b)) for a, b in ((ux, vx), (uy, vy), (uz, vz)))
    inv = prog.assign(div(const(1.0), call("sqrt", add(mul(sx, sx), mul(sy, sy), mul(sz, sz)))))
    hx, hy, hz = (prog.assign(mul(c, inv)) for c in (sx, sy, sz))
    r2 = prog.assign(add(mul(hx, hx), mul(hy, hy)))
    tiny = const(1e-30)
    sin_t = prog.assign(select_gt(r2, tiny, call("sqrt", r2), const(0.0)))
    safe = prog.assign(select_gt(r2, tiny, sin_t, const(1.0)))
    cos_p = prog.assign(select_gt(r2, tiny, div(hx, safe), const(1.0)))
    sin_p = prog.assign(select_gt(r2, tiny, div(hy, safe), const(0.0)))
    x = prog.assign(add(mul(cos_p, ux), mul(sin_p, uy)))
    y = prog.assign(sub(mul(cos_p, uy), mul(sin_p, ux)))
    dx = prog.assign(sub(mul(x, hz), mul(uz, sin_t)))
    dz = prog.assign(add(mul(x, sin_t), mul(uz, hz)))
    inputs = [sin_t, None, hz, dx, y, dz]  # h_y = 0
    w1, b1, w2, b2, w3, b3 = (np.asarray(a, np.float64) for a in model.params)

    def dense(xs, w, b, relu):
        out = []
        for k in range(w.shape[1]):
            z = add(*[mul(xi, const(w[i, k])) for i, xi in enumerate(xs) if xi is not None], const(b[k]))
            out.append(prog.assign(call("max", z, const(0.0)) if relu else z))
        return out

    a1 = dense(inputs, w1, b1, True)
    a2 = dense(a1, w2, b2, True)
    z3 = dense(a2, w3, b3, False)
    outs = [prog.assign(call("max", sub(call("exp", z), const(1.0)), const(0.0)), prefix="f") for z in z3]
    prog.output([where_positive(var("uz"), var("vz"), f) for f in outs])
    return prog


def program(model) -> Program:
    """The :class:`Program` of a :class:`polyjax.PolynomialBRDF` or a ``polyjax.data.NeuralBRDF``."""
    if isinstance(model, NeuralBRDF):
        return neural_program(model)
    if isinstance(model, PolynomialBRDF):
        return polynomial_program(model)
    raise InputError(f"model: expected a polyjax.PolynomialBRDF or polyjax.data.NeuralBRDF, found "
                     f"{type(model).__name__} (other BRDFs: use merl_binary, or the Mitsuba plugin's tabulation)")


def polynomial_program(model: PolynomialBRDF) -> Program:
    """The :class:`Program` of a polynomial model of batch shape ``()``, ``(1,)`` (grey) or ``(3,)`` (RGB)."""
    if not isinstance(model, PolynomialBRDF):
        raise InputError(f"model: expected a polyjax.PolynomialBRDF, found {type(model).__name__}")
    bs = model.batch_shape
    if bs not in ((), (1,), (3,)):
        raise InputError(f"model: expected batch shape () or (1,) or (3,) (channels), found {bs}; select one "
                         "material first, e.g. model[i]")
    prog = Program()
    u = _unit(prog, INPUTS[:3])
    v = _unit(prog, INPUTS[3:])
    x = _variables(prog, model.variables, u, v)
    lanes = [_channel(prog, model, c, x) for c in range(int(np.prod(bs, dtype=int)))]
    if len(lanes) == 1:
        lanes = lanes * 3
    # clamped at 0 by the renderer's definition of light transport: a fitted polynomial may dip below 0, and a
    # shader or a renderer must never transport negative radiance
    prog.output([where_positive(var("uz"), var("vz"), transported_expression(f)) for f in lanes])
    return prog


__all__ = ["INPUTS", "OUTPUTS", "Program", "neural_program", "polynomial_program", "program"]
