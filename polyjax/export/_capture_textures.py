"""The texture files of a capture fit, written into one folder (:func:`write_capture_textures`): what
``polyjax fit-photos`` writes beside a fit made without scanned normals.

Files (image order, row 0 at the top; PNGs 16-bit unless ``bits=8``, linear unless said):

- ``normal.png``, ``normal.exr``: the tangent-space normal map of the image plane (:mod:`polyjax.export.normal_map`:
  ``n * 0.5 + 0.5``, ``x`` right, ``y`` up, ``z`` towards the camera, equal to the camera frame);
- ``diffuse.exr``: the diffuse albedo ``rho_d`` in the capture's units (the BRDF's diffuse term is ``rho_d / pi``),
  ``diffuse.png`` the same divided by the card's scale, sRGB-encoded 8-bit with the mask as alpha;
- ``basecolor.png`` (sRGB, 8-bit, alpha = mask), ``roughness.png``, ``metallic.png`` and ``material.exr``
  (channels ``R, G, B`` base colour, ``roughness``, ``metallic``, ``A`` mask): the glTF metallic-roughness maps of
  :func:`polyjax.export.card_maps` (the ``.glb`` card's textures);
- ``mix.exr`` (channels ``mix0 ... mix{K-1}``) and ``mix0.png`` ...: the per-pixel weights of the shared lobes
  (each PNG divided by its own maximum, written in ``mix.json`` with the GGX fits of the lobes).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from .._errors import InputError
from .._files import write_atomically
from ._card_maps import CardMaps, card_maps
from ._normal_map import normal_map
from ._texture import write_texture


def _mix_files(folder: Path, fit, maps: CardMaps, bits: int) -> list[Path]:
    mix = np.where(np.asarray(fit.mask)[..., None], np.maximum(np.asarray(fit.mix, np.float64), 0.0), 0.0)
    k = mix.shape[-1]
    peaks = [float(np.max(mix[..., i], initial=0.0)) for i in range(k)]
    out = [write_texture(folder / "mix.exr", mix, channels=tuple(f"mix{i}" for i in range(k)))]
    out += [write_texture(folder / f"mix{i}.png", mix[..., i] / max(p, 1e-300), bits=bits)
            for i, p in enumerate(peaks)]
    info = {"pngPeak": peaks, "lobeRoughness": np.asarray(maps.lobes.roughness).tolist(),
            "lobeAmplitude": np.asarray(maps.lobes.amplitude).tolist(),
            "lobeRelativeL2": np.asarray(maps.lobes.relative_l2).tolist(), "lightScale": float(maps.scale)}
    text = json.dumps(info, indent=1)
    out.append(write_atomically(folder / "mix.json", lambda tmp: tmp.write_text(text)))
    return out


def write_capture_textures(fit, folder, *, bits: int = 16, maps: CardMaps | None = None) -> dict[str, Path]:
    """Write the texture files of a capture fit (module notes) into ``folder``.

    Args:
        fit: a :class:`polyjax.CaptureFit` (or an object with its fields and ``lobes``).
        folder: an existing folder.
        bits: 8 or 16, the linear PNGs' bit depth (the sRGB colour PNGs are 8-bit).
        maps: the :func:`~polyjax.export.card_maps` of ``fit``, if already made.

    Returns:
        ``{file name: path}`` of the files written (each whole or not at all).

    Raises:
        InputError: ``folder`` is not a folder, ``bits`` is not 8 or 16, ``fit`` lacks a capture fit's field.
    """
    folder = Path(folder)
    if not folder.is_dir():
        raise InputError(f"folder: expected an existing folder, found {str(folder)!r}")
    if bits not in (8, 16):
        raise InputError(f"bits: expected 8 or 16, found {bits!r}")
    maps = card_maps(fit) if maps is None else maps
    m = np.asarray(maps.mask)
    alpha = m[..., None].astype(float)
    rho = np.where(m[..., None], np.maximum(np.asarray(fit.diffuse, np.float64), 0.0), 0.0)
    base = np.asarray(maps.base_color)
    material = np.concatenate([base, np.asarray(maps.roughness)[..., None], np.asarray(maps.metallic)[..., None],
                               alpha], -1)
    out = [normal_map(maps.normals, folder / "normal.png", mask=m, bits=bits),
           normal_map(maps.normals, folder / "normal.exr", mask=m),
           write_texture(folder / "diffuse.exr", rho),
           write_texture(folder / "diffuse.png", np.concatenate([rho / maps.scale, alpha], -1), srgb=True),
           write_texture(folder / "basecolor.png", np.concatenate([base, alpha], -1), srgb=True),
           write_texture(folder / "roughness.png", maps.roughness, bits=bits),
           write_texture(folder / "metallic.png", maps.metallic, bits=bits),
           write_texture(folder / "material.exr", material, channels=("R", "G", "B", "roughness", "metallic", "A"))]
    out += _mix_files(folder, fit, maps, bits)
    return {p.name: p for p in out}
