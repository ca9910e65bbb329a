"""The ``polyjax render`` command on the built-in synthetic data."""

import numpy as np

import polyjax.render as pr
from polyjax.cli import main


def test_render_command_writes_grid_and_psnr(tmp_path, capsys, monkeypatch):
    monkeypatch.delenv("POLYJAX_DATA", raising=False)
    out = tmp_path / "grid"
    assert main(["render", "--degrees", "1,4", "--reference", "--size", "16", "--out", str(out)]) == 0
    img = pr.read_exr(out.with_suffix(".exr"))
    assert img.shape == (3 * 16 + 4 * 2, 3 * 16 + 4 * 2, 3)  # rows: measured, p=1, p=4; three materials
    assert out.with_suffix(".png").stat().st_size > 0
    text = capsys.readouterr().out
    assert "rows: measured, p=1, p=4" in text and "effects: direct_point" in text
    assert text.count("PSNR vs measured") == 3
    assert (tmp_path / "grid_0_compare.png").exists()
    assert np.isfinite(img).all() and img.max() > 0


def test_render_out_with_a_suffix_names_every_file_from_the_same_prefix(tmp_path, capsys, monkeypatch):
    """``--out grid.exr`` writes ``grid.exr``, ``grid.png`` and ``grid_0_compare.png`` (not ``grid.exr_0_...``)."""
    monkeypatch.delenv("POLYJAX_DATA", raising=False)
    assert main(["render", "--degrees", "1", "--reference", "--size", "8", "--out", str(tmp_path / "grid.exr")]) == 0
    capsys.readouterr()
    names = sorted(p.name for p in tmp_path.iterdir())
    assert names == ["grid.exr", "grid.png", "grid_0_compare.png", "grid_1_compare.png", "grid_2_compare.png"]
