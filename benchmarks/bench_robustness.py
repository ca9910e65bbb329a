"""Conditioning and float32 accuracy of the polynomial fit at high degree (p = 1..15).

For Quarry tile (CUReT sample 25) and neural MERL green-latex (a reproducible 20,000-bin subset, so
the tall CholeskyQR2 path runs), per variable set and degree: the worst condition number over
lanes of the weighted, column-equilibrated design with the default scaled-Legendre basis and with
the paper's monomials, and the worst ratio L2(float32) / L2(float64) (both bases), all measured in
this run.

    python benchmarks/bench_robustness.py [--variables lafortune] [--subsample 20000]
"""

from __future__ import annotations

import argparse

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

import polyjax as pj  # noqa: E402

DEGREES = list(range(1, 16))


def measure(d: pj.Measurements, variables: str) -> dict:
    out = {}
    for basis in ("legendre", "monomial"):
        for dtype in (jnp.float64, jnp.float32):
            m = pj.fit_polynomial(
                jnp.asarray(d.u, dtype), jnp.asarray(d.v, dtype), jnp.asarray(d.values, dtype),
                weights=jnp.asarray(d.weights, dtype), mask=d.mask, variables=variables, degree=DEGREES, basis=basis,
            )
            out[basis, dtype.__name__] = m
    rows = []
    for i, p in enumerate(DEGREES):
        row = {"p": p}
        for basis in ("legendre", "monomial"):
            m64, m32 = out[basis, "float64"], out[basis, "float32"]
            row[f"cond_{basis}"] = float(np.max(np.asarray(m64.condition)[i]))
            r = np.asarray(m32.l2)[i] / np.asarray(m64.l2)[i]
            row[f"ratio_{basis}"] = float(r[np.argmax(np.abs(np.log(r)))])
            row[f"rd32_{basis}"] = int(np.sum(np.asarray(m32.status)[i] != pj.RESULTS.OK))
        rows.append(row)
    return rows


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--variables", nargs="*", default=list(pj.variable_sets()))
    ap.add_argument("--subsample", type=int, default=20000)
    args = ap.parse_args(argv)
    sets = {
        "Quarry tile (CUReT 25)": pj.data.load("curet:25"),
        f"green-latex ({args.subsample} bins, RGB)": pj.data.load("merl-nbrdf:green-latex", subsample=args.subsample,
                                                                 seed=0),
    }
    summary = []
    for title, d in sets.items():
        for var in args.variables:
            rows = measure(d, var)
            print(f"\n{title}, {var}")
            print("  p | cond Legendre | cond monomial | f32/f64 L2 Legendre | f32/f64 L2 monomial | "
                  "f32 not OK (leg/mono)")
            for r in rows:
                print(f"{r['p']:3d} | {r['cond_legendre']:13.3g} | {r['cond_monomial']:13.3g} | "
                      f"{r['ratio_legendre']:19.7f} | {r['ratio_monomial']:19.7f} | "
                      f"{r['rd32_legendre']}/{r['rd32_monomial']}")
            summary.append((title, var, max(r["cond_legendre"] for r in rows), max(r["cond_monomial"] for r in rows),
                            max(abs(np.log(r["ratio_legendre"])) for r in rows),
                            max(abs(np.log(r["ratio_monomial"])) for r in rows)))
    print("\nworst over p = 1..15")
    print("data | variables | cond Legendre | cond monomial | worst f32/f64 L2 Legendre | monomial")
    for t, v, cl, cm, rl, rm in summary:
        print(f"{t} | {v} | {cl:.3g} | {cm:.3g} | {np.exp(rl):.6f} | {np.exp(rm):.4f}")


if __name__ == "__main__":
    main()
