"""baselines: the nonlinear BRDF models the paper compares with, and Zernike polynomials.

Every model is a pure JAX function ``f(params, u, v)`` (constrained parameters, directions
``(..., 3)`` in the local frame, normal ``+z``, ``u`` light, ``v`` view), registered by name in
:data:`MODELS`. :func:`fit` fits any of them to measurements with the same objective as
:func:`polyjax.fit_polynomial` (paper equation (11), 80-degree cutoff) by batched multi-start
Levenberg-Marquardt; Zernike is linear and solved in closed form. ``"sgd"`` and ``"abc"`` are the
compact models whose fits of the 100 MERL materials are published (:func:`published`). Enable float64 in your entry
point (``jax.config.update("jax_enable_x64", True)``).
"""

import warnings

from polyjax import RESULTS

from ._aot import SavedProgramWarning
from ._fit import fit
from ._fit_images import fit_to_images
from ._models.abc import abc
from ._models.ashikhmin_shirley import ashikhmin_shirley
from ._models.blinn_phong import blinn_phong
from ._models.common import BaselineModel, Transform
from ._models.cook_torrance import cook_torrance
from ._models.gltf_pbr import gltf_brdf, gltf_pbr
from ._models.lafortune import lafortune
from ._models.lafortune_anisotropic import lafortune_anisotropic
from ._models.openpbr import open_pbr_surface
from ._models.oren_nayar import oren_nayar
from ._models.principled import principled, principled_brdf
from ._models.registry import MODELS, NONLINEAR_MODELS, PAPER_MODELS, STANDARD_MODELS, get_model
from ._models.sgd import sgd
from ._models.usd_preview import usd_preview_surface
from ._models.ward import ward
from ._models.ward_anisotropic import ward_anisotropic
from ._models.ward_duer import ward_duer
from ._models.zernike import disk_point, n_zernike_terms, zernike, zernike_design, zernike_terms
from ._multistart import BACKENDS, residuals
from ._published import published, published_materials
from ._result import BaselineFit, standard_material
from ._saving import KIND as SAVED_MODEL_KIND
from ._solver import MultiStart
from ._starts import initial_guesses


def __getattr__(name):
    if name == "BaselineStatus":  # a former name of polyjax.RESULTS
        warnings.warn("baselines.BaselineStatus is deprecated: use polyjax.RESULTS", DeprecationWarning, stacklevel=2)
        return RESULTS
    raise AttributeError(f"module 'baselines' has no attribute {name!r}")


__all__ = [
    "BACKENDS", "SAVED_MODEL_KIND", "BaselineFit", "BaselineModel", "MODELS", "MultiStart", "NONLINEAR_MODELS",
    "PAPER_MODELS", "Transform", "abc", "ashikhmin_shirley", "blinn_phong", "cook_torrance", "disk_point", "fit",
    "fit_to_images", "get_model", "initial_guesses", "lafortune", "lafortune_anisotropic", "n_zernike_terms",
    "oren_nayar", "published", "published_materials", "residuals", "sgd", "ward", "ward_anisotropic", "ward_duer",
    "zernike", "zernike_design", "zernike_terms",
]
__all__ += ["SavedProgramWarning"]
__all__ += ["STANDARD_MODELS", "gltf_brdf", "gltf_pbr", "principled", "principled_brdf", "standard_material"]
__all__ += ["open_pbr_surface", "usd_preview_surface"]
