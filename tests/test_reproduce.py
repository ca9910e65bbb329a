"""``python benchmarks/reproduce.py --quick``: every table, figure and the JSON are written, with finite numbers."""

import json
import math

import numpy as np
import pytest

from benchmarks.paper.constants import PAPER_TABLE2, PAPER_TABLE3, PAPER_TABLE4


def test_pareto_front():
    # the reproduction's modules imported in the tests, not at the top: every xdist worker imports this file to
    # collect, and its figures import matplotlib.pyplot (about 1.9 s of a worker's start)
    from benchmarks.paper.figures import pareto_front

    pts = [(1.0, 5.0), (2.0, 3.0), (3.0, 4.0), (0.5, 6.0), (4.0, 1.0), (2.0, 2.5)]
    assert sorted(pareto_front(pts)) == [0, 3, 4, 5]


def test_paper_constants_complete():
    assert len(PAPER_TABLE2) == 11 and all(len(r) == 5 for r in PAPER_TABLE2.values())
    assert len(PAPER_TABLE3) == 10 and all(len(r) == 6 for r in PAPER_TABLE3.values())
    assert len(PAPER_TABLE4) == 10
    assert PAPER_TABLE3["poly:ward:5"][3] == (0.0026, 49.557)


def _numbers(obj):
    if isinstance(obj, dict):
        for v in obj.values():
            yield from _numbers(v)
    elif isinstance(obj, list):
        for v in obj:
            yield from _numbers(v)
    elif isinstance(obj, (int, float)) and not isinstance(obj, bool):
        yield obj


@pytest.mark.data
@pytest.mark.slow
def test_reproduce_quick(tmp_path, data_root):
    from benchmarks.paper.run import main

    out = tmp_path / "res"
    assert main(["--quick", "--out", str(out), "--data-root", str(data_root)]) == 0
    for name in ("table1.md", "table2.md", "table3.md", "table4.md", "lowest_counts.md", "references.md", "report.md",
                 "accuracy_vs_time.md", "accuracy_vs_time.png", "fig6_curet52.png", "fig7_linear_models.png",
                 "fig3_curet_spheres.png", "fig3_curet_spheres.exr", "fig5_blue_metallic_paint.png",
                 "fig5_blue_metallic_paint.exr", "fig8_reciprocity.png", "fig8_reciprocity.exr", "results.json"):
        assert (out / name).stat().st_size > 0, name
    res = json.loads((out / "results.json").read_text())
    # no NaN/inf anywhere (they would be written as null), and every table populated
    nums = list(_numbers(res))
    assert nums and all(math.isfinite(x) for x in nums)
    t1 = res["table1"]
    assert len(t1["quarry_tile"]) == 6 and all(0 < x < 0.05 for x in t1["quarry_tile"])
    assert np.all(np.diff(t1["quarry_tile"]) <= 1e-12)  # nested models: L2 never grows with p
    assert t1["n_params_kp1"] == [3, 5, 7, 9, 11, 13] and t1["n_params_paper_column"] == [7, 9, 11, 13, 15, 17]
    for table, n_cols in (("table2", 5), ("table3", 2)):
        for key, row in res[table]["rows"].items():
            ours = row["ours"] if table == "table2" else row["ours_l2"]
            assert len(ours) == n_cols and all(x is not None and 0 < x < 1 for x in ours), (table, key)
    for row in res["table3"]["rows"].values():
        assert all(p is not None and 5 < p < 100 for p in row["ours_psnr"])
    for key, row in res["table4"]["rows"].items():
        assert row["ours_s"] is not None and row["ours_s"] > 0, key
    # Fig. 8: the polynomial model is reciprocal, so the swapped rendering is the same image
    fig8 = res["renders"]["fig8"]
    assert fig8["max_abs_pixel_difference_swapped"] <= 1e-4 * max(fig8["max_pixel"], 1.0)
    # the numpy loop solves the same problems
    for ds in res["references"]["numpy"].values():
        assert all(c["max_rel_l2_difference"] < 1e-6 for c in ds["configs"].values())
    assert res["accuracy_vs_time"]["CUReT"]["front"] and res["accuracy_vs_time"]["MERL (neural)"]["front"]
    assert "| Poly. (Lafortune, p = 7) | Quarry Tile |" in (out / "table2.md").read_text()
