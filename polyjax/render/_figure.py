"""The comparison figure of the paper's Fig. 4 (matplotlib, without pyplot: no global backend or figure manager).

This module alone imports matplotlib (about 0.3 s), so :mod:`polyjax.render` loads it on first use of
:func:`comparison_figure` (its package face's ``__getattr__``)."""

from __future__ import annotations

import os
from typing import Sequence

import numpy as np
from jaxtyping import ArrayLike
from matplotlib.figure import Figure

from .._errors import InputError
from .._files import check_output_path, write_atomically
from .._metrics import psnr
from ._image import difference_images, to_srgb


def comparison_figure(path: str | os.PathLike, reference: ArrayLike, images: Sequence[ArrayLike],
                      names: Sequence[str], reference_name: str = "measured", exposure: float = 0.0,
                      tonemap: str = "clip", mask: ArrayLike | None = None) -> dict[str, float]:
    """Save a figure like the paper's Fig. 4: the reference beside each model's rendering, each with
    its difference image (common scale) and its PSNR in dB against the reference (Table 3).

    PSNR is computed on the tone-mapped sRGB images (peak 1), optionally only inside ``mask``.

    Returns:
        ``{name: psnr_dB}``.
    """
    path = check_output_path(path, "path")
    if len(names) != len(images):
        raise InputError(f"names: expected {len(images)} names (one per image), found {len(names)}")
    ref_d = to_srgb(reference, exposure, tonemap)
    disp = [to_srgb(im, exposure, tonemap) for im in images]
    diffs, scale = difference_images(disp, ref_d)
    m = None if mask is None else np.asarray(mask)[..., None]
    scores = {n: float(psnr(d, ref_d, peak=1.0, mask=m)) for n, d in zip(names, disp)}
    k = len(images) + 1
    fig = Figure(figsize=(2.2 * k, 4.6))  # no pyplot: no global backend or figure manager
    ax = fig.subplots(2, k, squeeze=False)
    ax[0, 0].imshow(ref_d)
    ax[0, 0].set_title(reference_name, fontsize=9)
    ax[1, 0].text(0.5, 0.5, f"|difference|\nscale 0..{scale:.3g}", ha="center", va="center", fontsize=8)
    for j, (n, d, df) in enumerate(zip(names, disp, diffs), start=1):
        ax[0, j].imshow(d)
        ax[0, j].set_title(f"{n}\n{scores[n]:.2f} dB", fontsize=9)
        ax[1, j].imshow(df, cmap="inferno", vmin=0.0, vmax=1.0)
    for a in ax.ravel():
        a.set_axis_off()
    fig.tight_layout()
    write_atomically(path, lambda tmp: fig.savefig(str(tmp), dpi=100))  # the format by the suffix, kept
    return scores


__all__ = ["comparison_figure"]
