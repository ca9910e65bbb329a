"""The table of baseline models by name."""

from __future__ import annotations

import numpy as np

from polyjax import UnknownNameError

from . import abc as _abc
from . import ashikhmin_shirley as _ashikhmin_shirley
from . import blinn_phong as _blinn_phong
from . import cook_torrance as _cook_torrance
from . import gltf_pbr as _gltf_pbr
from . import lafortune as _lafortune
from . import lafortune_anisotropic as _lafortune_anisotropic
from . import openpbr as _openpbr
from . import oren_nayar as _oren_nayar
from . import principled as _principled
from . import rough_conductor as _rough_conductor
from . import rough_plastic as _rough_plastic
from . import sgd as _sgd
from . import usd_preview as _usd_preview
from . import ward as _ward
from . import ward_anisotropic as _ward_anisotropic
from . import ward_duer as _ward_duer
from .common import REAL, BaselineModel
from .joint import SUFFIX, joint_model
from .zernike import n_zernike_terms, zernike

ZERNIKE = BaselineModel(
    name="zernike",
    param_names=tuple(f"c{j}" for j in range(n_zernike_terms(8))),
    transforms=(REAL,) * n_zernike_terms(8),
    evaluate=zernike,
    n_linear=n_zernike_terms(8),
    columns=None,
    guesses=np.zeros((1, 0)),
    sample=None,
    reference="Koenderink, van Doorn, Stavridi, ECCV 1996",
    linear=True,
)

_ALL = (
    _ashikhmin_shirley.MODEL, _blinn_phong.MODEL, _cook_torrance.MODEL, _lafortune.MODEL, _oren_nayar.MODEL,
    _ward.MODEL, _ward_duer.MODEL, ZERNIKE, _lafortune_anisotropic.MODEL, _ward_anisotropic.MODEL,
    _sgd.MODEL, _abc.MODEL,
    _openpbr.MODEL, _openpbr.ANISOTROPIC, _openpbr.COAT, _usd_preview.MODEL, _usd_preview.SPECULAR,
    _usd_preview.CLEARCOAT,
)
_ALL += (_gltf_pbr.MODEL, _gltf_pbr.SPECULAR, _gltf_pbr.ANISOTROPIC, _principled.MODEL, _principled.ANISOTROPIC)
_ALL += (_rough_conductor.MODEL, _rough_conductor.BECKMANN, _rough_plastic.MODEL)
REGISTRY: dict[str, BaselineModel] = {m.name: m for m in _ALL}

#: Every model name accepted by :func:`baselines.fit` and :func:`baselines.get_model`.
MODELS: tuple[str, ...] = tuple(REGISTRY)
#: The paper's seven nonlinear models plus Zernike (its Table 2 rows), isotropic.
PAPER_MODELS: tuple[str, ...] = MODELS[:8]
#: The paper's nonlinear isotropic models (fitted by Levenberg-Marquardt); ``"sgd"`` and ``"abc"`` (the
#: published compact models of the 100 MERL materials, :func:`baselines.published`) come after them.
NONLINEAR_MODELS: tuple[str, ...] = MODELS[:7]
#: The standard material models (one roughness, metallic, ... for R, G, B: fitted jointly over the channels).
STANDARD_MODELS: tuple[str, ...] = tuple(m.name for m in _ALL if m.shared_across_channels)
# their joint R, G, B records, found by get_model under "<name>:rgb" (baselines._models.joint)
_JOINT = {m.name + SUFFIX: joint_model(m) for m in _ALL if m.shared_across_channels}



def get_model(name: str) -> BaselineModel:
    """The :class:`BaselineModel` record of ``name`` (case and ``_``/space insensitive)."""
    key = str(name).strip().lower().replace("_", "-").replace(" ", "-")
    if key in _JOINT:
        return _JOINT[key]
    if key not in REGISTRY:
        raise UnknownNameError(f"baseline model {name!r}: expected one of {list(MODELS)}")
    return REGISTRY[key]
