"""polyjax: fit reflectance models (BRDFs) to measured data in JAX.

Implements Ozturk, Kurt, Bilgili, Gungor, "Linear approximation of Bidirectional Reflectance
Distribution Functions", Computers & Graphics 32 (2008): a polynomial response surface in the
principal components of explanatory variables of (u, v), fitted in closed form by weighted
least squares. Enable float64 in your entry point (``jax.config.update("jax_enable_x64", True)``)
for fitting; polyjax does not change global JAX settings on import.
"""

from . import data
from ._approx import ApproximationError, approximation_error
from ._basis import design_matrix, exponents, n_terms
from ._cache import CACHE_ENV, default_cache_dir, enable_compilation_cache
from ._capture import Capture, relight
from ._config import DATA_ENV, data_root, has_data_root
from ._design import fitted_design
from ._errors import DataFormatError, DataNotFoundError, FitError, InputError, PolyjaxError, UnknownNameError
from ._fit import fit_polynomial, n_parameters
from ._fit_images import fit_polynomial_to_images
from ._geometry import (
    cartesian_to_spherical,
    cos_theta,
    cutoff_mask,
    half_vector,
    reflect,
    safe_normalize,
    spherical_to_cartesian,
)
from ._image_rows import ImageRows, image_rows
from ._inputs import PreparedInputs, check_parameter_count, is_concrete, prepare_inputs
from ._io import load_model, model_metadata, save_model
from ._kinds import ModelKind, model_kinds, register_model_kind
from ._logfit import fit_log_polynomial
from ._lstsq import LstsqSolution, weighted_lstsq
from ._measurements import Measurements, check_samples, make_measurements
from ._metrics import fit_weights, l2_error, psnr
from ._model import FitStatus, PolynomialBRDF, evaluate_paper_form
from ._pca import PCA, fit_pca
from ._results import RESULTS, Result, raise_on_status
from ._threads import THREADS_ENV, lapack_threads, one_lapack_thread
from ._variables import VariableSet, explanatory_variables, get_variables, register_variables, variable_sets

__version__ = "0.1.0"

# imported on first use: they pull in far more than a fit needs
_LAZY_SUBMODULES = ("export", "render", "svbrdf", "view")


def __getattr__(name):
    if name in _LAZY_SUBMODULES:
        import importlib

        module = importlib.import_module(f".{name}", __name__)
        globals()[name] = module
        return module
    raise AttributeError(f"module 'polyjax' has no attribute {name!r}")


def __dir__():
    return sorted(set(globals()) | set(_LAZY_SUBMODULES))


__all__ = [
    "ApproximationError", "CACHE_ENV", "DATA_ENV", "DataFormatError", "DataNotFoundError", "FitError", "FitStatus",
    "ImageRows", "InputError", "LstsqSolution", "Measurements", "ModelKind", "PCA", "PolyjaxError", "PolynomialBRDF",
    "PreparedInputs", "RESULTS", "Result", "UnknownNameError", "VariableSet", "approximation_error",
    "cartesian_to_spherical", "check_parameter_count", "check_samples", "cos_theta", "cutoff_mask", "data",
    "data_root", "default_cache_dir", "design_matrix", "enable_compilation_cache", "evaluate_paper_form",
    "explanatory_variables", "export", "exponents", "fit_log_polynomial", "fit_pca", "fit_polynomial",
    "fit_polynomial_to_images", "fit_weights", "fitted_design", "get_variables", "half_vector", "has_data_root",
    "image_rows", "is_concrete", "l2_error", "load_model", "make_measurements", "model_kinds", "n_parameters",
    "n_terms",
    "prepare_inputs", "psnr", "raise_on_status", "reflect", "register_model_kind", "register_variables", "render",
    "safe_normalize", "save_model", "spherical_to_cartesian", "svbrdf", "variable_sets", "weighted_lstsq",
    "THREADS_ENV", "lapack_threads", "one_lapack_thread", "view",
    "Capture", "relight", "model_metadata",
]
