"""A capture fit's files out of the command line: the texture folder ``polyjax fit-photos`` writes beside a fit made
without scanned normals (:func:`write_textures_beside`), and the ``.glb`` card of
``polyjax export FIT --to gltf`` when ``FIT`` is a saved capture fit (:func:`capture_fit_of`,
:func:`run_card_export`)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

import polyjax as pj

from .. import export

_FIELDS = ("normals", "mask", "diffuse", "mix", "lobes")


def is_capture_fit(model) -> bool:
    """Whether ``model`` has a capture fit's fields (:class:`polyjax.CaptureFit`'s contract)."""
    return all(hasattr(model, name) for name in _FIELDS)


def textures_folder(save: Path) -> Path:
    """The folder of textures beside the saved fit ``save``: ``<stem>_textures`` in its folder."""
    return save.with_name(f"{save.stem}_textures")


def write_textures_beside(fit, save: Path, *, bits: int = 16) -> dict[str, Path]:
    """Write the texture files of ``fit`` (:func:`polyjax.export.write_capture_textures`: normal map PNG and EXR,
    material maps) into :func:`textures_folder` of ``save`` (created)."""
    folder = textures_folder(Path(save))
    folder.mkdir(exist_ok=True)
    return export.write_capture_textures(fit, folder, bits=bits)


def capture_fit_of(source: str):
    """The capture fit saved in ``source`` (a ``.npz`` or ``.json`` model file), or None when it holds another
    model or is not a model file."""
    path = Path(source)
    if path.suffix.lower() not in (".npz", ".json") or not path.is_file():
        return None
    model = pj.load_model(path)
    return model if is_capture_fit(model) else None


def run_card_export(args, fit, out: Path) -> int:
    """``polyjax export FIT --to gltf`` of a capture fit: the ``.glb`` card (:func:`polyjax.export.gltf_card`)."""
    maps = export.card_maps(fit)
    export.gltf_card(fit, out, crop=not getattr(args, "full_image", False), maps=maps)
    lobes = maps.lobes
    print(f"capture fit {args.model}: {fit.mix.shape[-1]} shared lobes fitted by glTF's GGX lobe: roughness "
          + ", ".join(f"{x:.3f}" for x in np.asarray(lobes.roughness)) + "; relative L2 "
          + ", ".join(f"{x:.3g}" for x in np.asarray(lobes.relative_l2)))
    m = np.asarray(maps.mask)
    print(f"  texels: metallic > 0.5 on {float(np.mean(np.asarray(maps.metallic)[m] > 0.5)):.1%} of the mask, "
          f"median roughness {float(np.median(np.asarray(maps.roughness)[m])):.3f}; light scale {maps.scale:.4g} "
          "(render with lights this many times the capture's)")
    print(f"wrote {out} (gltf card)")
    return 0
