"""polyjax: fit reflectance models (BRDFs) to measured data in JAX.

Implements Ozturk, Kurt, Bilgili, Gungor, "Linear approximation of Bidirectional Reflectance
Distribution Functions", Computers & Graphics 32 (2008): a polynomial response surface in the
principal components of explanatory variables of (u, v), fitted in closed form by weighted
least squares. Enable float64 in your entry point (``jax.config.update("jax_enable_x64", True)``)
for fitting; polyjax does not change global JAX settings on import.
"""

from . import data, internal  # noqa: F401 - polyjax.internal: the API of extension packages
from ._approx import ApproximationError, approximation_error
from ._basis import design_matrix, exponents, n_terms
from ._cache.compilation import CACHE_ENV, default_cache_dir, enable_compilation_cache
from ._compact import BudgetError, CompactBRDF, compact_families, fit_compact
from ._config import DATA_ENV, data_root, has_data_root
from ._design import fitted_design
from ._directions import (
    cartesian_to_spherical,
    cos_theta,
    cutoff_mask,
    half_vector,
    reflect,
    safe_normalize,
    spherical_to_cartesian,
)
from ._errors import DataFormatError, DataNotFoundError, FitError, InputError, PolyjaxError, UnknownNameError
from ._fit.log import fit_log_polynomial
from ._fit.polynomial import fit_polynomial, n_parameters
from ._io import load_model, model_metadata, save_model
from ._measurements import Measurements, check_samples, make_measurements
from ._metrics import l2_error, log_error, psnr
from ._model import PolynomialBRDF, PolynomialSpec, evaluate_paper_form
from ._pca import PCA, fit_pca
from ._results import RESULTS, deprecated_alias
from ._solve.lstsq import LstsqSolution, weighted_lstsq
from ._solve.threads import THREADS_ENV, lapack_threads
from ._variables import VariableSet, explanatory_variables, get_variables, register_variables, variable_sets
from .internal import (  # noqa: F401 - public before: still importable from here, for extensions in internal
    ModelKind,
    PreparedInputs,
    check_parameter_count,
    fit_weights,
    is_concrete,
    model_kinds,
    one_lapack_thread,
    prepare_inputs,
    raise_on_status,
    register_model_kind,
)

__version__ = "0.1.0"

# imported on first use: they pull in far more than a fit needs
_LAZY_SUBMODULES = ("cli", "export", "inverse", "render", "svbrdf", "view")
#: names of the lazily imported ``inverse`` package offered here too (the fits from images, a capture)
_LAZY_NAMES = {"Capture": "inverse", "CaptureFit": "inverse", "ImageRows": "inverse", "fit_capture": "inverse",
               "fit_polynomial_to_images": "inverse", "image_rows": "inverse", "relight": "inverse"}


def __getattr__(name):
    if name in ("Result", "FitStatus"):  # former names of RESULTS
        return deprecated_alias("polyjax", name)
    if name in _LAZY_SUBMODULES or name in _LAZY_NAMES:
        import importlib  # the lazy package face: a submodule imported on first use

        module = importlib.import_module(f".{_LAZY_NAMES.get(name, name)}", __name__)
        value = getattr(module, name) if name in _LAZY_NAMES else module
        globals()[name] = value
        return value
    raise AttributeError(f"module 'polyjax' has no attribute {name!r}")


def __dir__():
    return sorted(set(globals()) | set(_LAZY_SUBMODULES) | set(_LAZY_NAMES))


__all__ = [
    "approximation_error", "ApproximationError", "BudgetError", "CompactBRDF", "compact_families",
    "CACHE_ENV", "Capture", "CaptureFit", "cartesian_to_spherical", "check_samples",
    "cos_theta", "cutoff_mask", "data", "DATA_ENV", "data_root", "DataFormatError", "DataNotFoundError",
    "default_cache_dir", "design_matrix", "enable_compilation_cache", "evaluate_paper_form", "explanatory_variables",
    "exponents", "export", "fit_capture", "fit_compact",
    "fit_log_polynomial", "fit_pca", "fit_polynomial", "fit_polynomial_to_images", "FitError",
    "fitted_design", "get_variables", "half_vector", "has_data_root", "image_rows", "ImageRows", "InputError",
    "inverse", "l2_error", "lapack_threads", "log_error", "load_model", "LstsqSolution", "make_measurements",
    "Measurements", "model_metadata", "n_parameters", "n_terms", "PCA", "PolyjaxError", "PolynomialBRDF",
    "PolynomialSpec", "psnr",
    "reflect", "register_variables",
    "relight", "render", "RESULTS", "safe_normalize", "save_model", "spherical_to_cartesian", "svbrdf", "THREADS_ENV",
    "UnknownNameError", "variable_sets", "VariableSet", "view", "weighted_lstsq"
]
