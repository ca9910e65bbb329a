"""Shared small data files for the data-loader tests: MERL tables of a reduced resolution, ASTM text."""

from __future__ import annotations

from pathlib import Path

import numpy as np

import polyjax as pj

SMALL_RES = (6, 5, 8)


def smooth_table(resolution=SMALL_RES, seed: int = 0) -> np.ndarray:
    """A (3, N) BRDF table in 1/sr on the bin centres: diffuse + a lobe around the half vector, with
    entries below the horizon set to -1 (MERL's missing) and a few random missing entries."""
    th, td, pd = pj.data.merl_bin_angles(resolution)
    base = np.array([0.2, 0.1, 0.05])[:, None] + np.array([1.0, 0.8, 0.6])[:, None] * np.cos(th)[None] ** 20
    vals = base * (1 + 0.1 * np.cos(pd))[None]
    u, v = pj.data.rusinkiewicz_to_directions(th, td, pd)
    below = (u[:, 2] <= 0) | (v[:, 2] <= 0)
    vals[:, below] = -1.0
    rng = np.random.default_rng(seed)
    vals[rng.integers(0, 3, 5), rng.integers(0, th.size, 5)] = -1.0
    return vals


def write_small_merl(path: Path, resolution=SMALL_RES, seed: int = 0) -> np.ndarray:
    vals = smooth_table(resolution, seed)
    pj.data.write_merl_binary(path, vals, resolution=resolution, mask=vals >= 0)
    return vals


def write_astm(path: Path, angles: np.ndarray, values: np.ndarray, names, n_points=None, degrees=False) -> Path:
    """An ASTM E1392-style file: header lines, VARS, then comma-separated rows."""
    ang = np.rad2deg(angles) if degrees else angles
    lines = ["NAME synthetic test sample", "SOURCE polyjax tests", "MEASUREMENT_METHOD gonioreflectometer"]
    lines.append(f"NUM_POINTS {len(ang) if n_points is None else n_points}")
    lines.append("VARS " + ",".join(["theta_i", "phi_i", "theta_s", "phi_s", *names]))
    for a, v in zip(ang, values):
        lines.append(",".join(f"{x:.9g}" for x in (*a, *v)))
    path.write_text("\n".join(lines) + "\n")
    return path
