"""The model's definition (``pj.PolynomialSpec``) and the solver's settings (``baselines.MultiStart``) as values:
the same fits as the keyword form, bit for bit; shared by fitted and saved models and the command line; bad fields
and a definition given twice refused, naming the field."""

from __future__ import annotations

import dataclasses
import functools
import json

import jax
import numpy as np
import pytest

import baselines as bl
import polyjax as pj
import polyjax.render as pr
from polyjax.cli import main

from _problems import curet, random_hemisphere
from _render_problems import lone_sphere

SPECS = {
    "lafortune p=5": pj.PolynomialSpec("lafortune", 5),
    "ward degrees 1-3, monomial": pj.PolynomialSpec("ward", (1, 2, 3), basis="monomial"),
    "rusinkiewicz p=4 interactions log": pj.PolynomialSpec("rusinkiewicz", 4, interactions=True, link="log", eps=0.01),
    "ashikhmin-shirley p=6 clamped": pj.PolynomialSpec("as", 6, clamp=True),
}


def _same_model(a, b) -> None:
    assert jax.tree.structure(a) == jax.tree.structure(b)
    for x, y in zip(jax.tree.leaves(a), jax.tree.leaves(b)):
        np.testing.assert_array_equal(np.asarray(x), np.asarray(y))


@pytest.mark.parametrize("name", sorted(SPECS))
def test_spec_fits_equal_the_keyword_form_and_come_back_from_the_model(name):
    spec, data = SPECS[name], curet((25, 33))
    keywords = pj.fit_polynomial(data, **spec.to_dict())
    given = pj.fit_polynomial(data, spec=spec)
    _same_model(given, keywords)
    assert given.spec == dataclasses.replace(spec, degree=max(np.atleast_1d(spec.degree)))
    if spec.link == "log":
        _same_model(pj.fit_log_polynomial(data, spec=spec), given)


def test_spec_from_a_fitted_or_saved_model_refits_the_same_family(tmp_path):
    data = curet((25,))
    first = pj.fit_polynomial(data, variables="as", degree=6, interactions=True)
    assert first.spec == pj.PolynomialSpec("ashikhmin-shirley", 6, interactions=True)
    back = pj.load_model(pj.save_model(tmp_path / "m.json", first))
    assert back.spec == first.spec and hash(back.spec) == hash(first.spec)
    _same_model(pj.fit_polynomial(data, spec=back.spec), first)
    assert pj.PolynomialSpec.from_dict(json.loads(json.dumps(first.spec.to_dict()))) == first.spec


def test_spec_fit_from_images_equals_the_keyword_form():
    brdf = pr.rgb_brdf(pj.fit_polynomial(curet((25,)), variables="lafortune", degree=3)[0])
    scenes = [lone_sphere(brdf, [pr.PointLight(p, 20.0)]) for p in [(2.0, 1.0, 4.0), (-1.0, 2.0, 4.0)]]
    images = [pr.render(s).image for s in scenes]
    spec = pj.PolynomialSpec("lafortune", 3)
    _same_model(pj.fit_polynomial_to_images(scenes, images, spec=spec),
                pj.fit_polynomial_to_images(scenes, images, variables="lafortune", degree=3, interactions=False,
                                            link="identity", clamp=False))


def test_spec_is_a_static_value_under_jit():
    u, v = random_hemisphere(300, seed=3)
    values = np.exp(-4 * (1 - (u[:, 2] + v[:, 2]) / 2))

    @functools.partial(jax.jit, static_argnames="spec")  # hashable: a static argument
    def l2(values, spec):
        return pj.fit_polynomial(u, v, values, spec=spec).l2

    eager = float(pj.fit_polynomial(u, v, values, degree=4).l2)
    assert float(l2(values, spec=pj.PolynomialSpec("lafortune", 4))) == pytest.approx(eager, rel=1e-12)
    assert jax.tree.leaves(pj.PolynomialSpec()) == []


@pytest.mark.parametrize("fields, message", [
    (dict(variables="nope"), "variables 'nope'"), (dict(degree=-1), "degree: expected"),
    (dict(degree=2.5), "degree: expected"), (dict(basis="chebyshev"), "basis: expected"),
    (dict(interactions="yes"), "interactions: expected"), (dict(link="sqrt"), "link: expected"),
    (dict(eps=0.0), "eps: expected a positive"), (dict(basis="monomial", clamp=True), "clamp: only for the Legendre"),
])
def test_bad_spec_fields_are_refused_naming_the_field(fields, message):
    with pytest.raises(pj.PolyjaxError, match=message):
        pj.PolynomialSpec(**fields)


def test_a_definition_given_twice_is_refused_unless_it_agrees():
    data, spec = curet((25,)), pj.PolynomialSpec("ward", 3)
    with pytest.raises(pj.InputError, match=r"given twice, found degree=4 and spec.degree=3"):
        pj.fit_polynomial(data, degree=4, spec=spec)
    with pytest.raises(pj.InputError, match="spec: expected a polyjax.PolynomialSpec"):
        pj.fit_polynomial(data, spec={"variables": "ward"})
    with pytest.raises(pj.InputError, match="link='log'"):
        pj.fit_log_polynomial(data, spec=spec)
    _same_model(pj.fit_polynomial(data, variables="ward", degree=3, spec=spec), pj.fit_polynomial(data, spec=spec))
    with pytest.raises(pj.InputError, match="unknown fields"):
        pj.PolynomialSpec.from_dict({"variables": "ward", "order": 3})


def test_solver_settings_fit_as_the_keyword_form():
    data = curet((25,))
    solver = bl.MultiStart(n_starts=4, max_steps=40, refine=None)
    _same_model(bl.fit("ward", data, solver=solver), bl.fit("ward", data, n_starts=4, max_steps=40, refine=None))
    with pytest.raises(pj.InputError, match="given twice, found n_starts=8 and solver.n_starts=4"):
        bl.fit("ward", data, n_starts=8, solver=solver)
    for fields, message in [(dict(n_starts=0), "n_starts"), (dict(backend="scipy"), "backend: expected"),
                            (dict(max_steps=0), "max_steps: expected a positive"),
                            (dict(limit_steps=-1), "limit_steps: expected a non-negative"),
                            (dict(rtol=-1.0), "rtol: expected")]:
        with pytest.raises(pj.InputError, match=message):
            bl.MultiStart(**fields)


def test_command_line_model_options_make_the_spec(tmp_path, capsys):
    path = tmp_path / "m.npz"
    assert main(["fit", "--variables", "rusinkiewicz", "--degree", "3", "--interactions", "--link", "log",
                 "--eps", "0.01", "--clamp", "--save", str(path), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    spec = pj.PolynomialSpec("rusinkiewicz", 3, interactions=True, link="log", eps=0.01, clamp=True)
    assert out["spec"] == spec.to_dict() and pj.load_model(path).spec == spec
    assert main(["fit", "--eps", "0", "--link", "log"]) == 2
    assert "--eps: expected a positive offset" in capsys.readouterr().err
