"""Loaders for measured BRDF data; all return :class:`polyjax.Measurements`.

The data root is an argument (``root=``) or the environment variable ``POLYJAX_DATA``.
Datasets: CUReT (``load_curet``), MERL ``.binary`` files (``load_merl_binary``), neural BRDFs of any set in
the published format (``load_nbrdf``, ``load_nbrdf_measurements``) and the fits of the 100 MERL materials
(``load_merl_nbrdf``), Cornell gonioreflectometer files (``load_cornell``); one entry point
``load("kind:name")``; any BRDF callable as measurements: ``tabulate``.
"""

from .._config import DATA_ENV, data_root, has_data_root
from ._colour import (
    CIE1931_CMF,
    CMF_WAVELENGTHS,
    XYZ_TO_SRGB,
    spectral_to_luminance,
    spectral_to_rgb,
    spectral_to_xyz,
    xyz_to_rgb_matrix,
)
from ._cornell import CORNELL_NAMES, load_cornell, read_cornell_astm, read_cornell_pbrt
from ._curet import (
    ANISOTROPIC_SAMPLES,
    ISOTROPIC_52,
    TABLE2_SAMPLES,
    ZOOMED_DUPLICATES,
    curet_sample_names,
    load_curet,
    read_curet_geometry,
)
from ._errors import (
    EmptyFileError,
    HeaderError,
    NonFiniteValueError,
    TruncatedFileError,
    UnknownMaterialError,
    WrongFormatError,
)
from ._load import CURET_SETS, dataset_spec, load
from ._merl import (
    MERL_N_BINS,
    MERL_NAMES,
    MERL_RESOLUTION,
    MERL_SCALE,
    TABLE3_MATERIALS,
    directions_to_rusinkiewicz,
    load_merl_binary,
    merl_bin_angles,
    merl_bin_weights,
    merl_grid,
    merl_index,
    read_merl_binary,
    rusinkiewicz_to_directions,
    write_merl_binary,
)
from ._nbrdf import (
    NeuralBRDF,
    load_merl_nbrdf,
    load_nbrdf,
    load_nbrdf_measurements,
    merl_nbrdf_path,
    nbrdf_names,
    resolve_merl_name,
)
from ._rgl import RGLBRDF, load_rgl, read_rgl, resolve_rgl_path
from ._synthetic import synthetic_default
from ._tabulate import tabulate

#: the photographs' loaders, imported on first use: a capture is rendered by polyjax.render (polyjax.inverse)
_LAZY_NAMES = ("PNG16_MAX", "check_png_header", "load_photometric", "resolve_photometric_folder", "read_mat_array",
               "read_png")


def __getattr__(name):
    if name in _LAZY_NAMES:
        import importlib  # the lazy package face: the photographs' module imported on first use

        value = getattr(importlib.import_module("._photometric", __name__), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'polyjax.data' has no attribute {name!r}")


def __dir__():
    return sorted(set(globals()) | set(_LAZY_NAMES))


__all__ = [
    "DATA_ENV", "data_root", "has_data_root", "ANISOTROPIC_SAMPLES", "ISOTROPIC_52", "TABLE2_SAMPLES",
    "ZOOMED_DUPLICATES", "curet_sample_names", "load_curet", "read_curet_geometry", "synthetic_default", "load",
    "CURET_SETS", "dataset_spec",
    "CIE1931_CMF", "CMF_WAVELENGTHS", "XYZ_TO_SRGB", "spectral_to_luminance", "spectral_to_rgb", "spectral_to_xyz",
    "xyz_to_rgb_matrix", "CORNELL_NAMES", "load_cornell", "read_cornell_astm", "read_cornell_pbrt",
    "EmptyFileError", "HeaderError", "NonFiniteValueError", "TruncatedFileError", "UnknownMaterialError",
    "WrongFormatError", "MERL_N_BINS", "MERL_NAMES", "MERL_RESOLUTION", "MERL_SCALE", "TABLE3_MATERIALS",
    "directions_to_rusinkiewicz", "load_merl_binary", "merl_bin_angles", "merl_bin_weights", "merl_grid",
    "merl_index", "read_merl_binary", "rusinkiewicz_to_directions", "write_merl_binary", "NeuralBRDF",
    "load_merl_nbrdf", "load_nbrdf", "load_nbrdf_measurements", "merl_nbrdf_path", "nbrdf_names", "resolve_merl_name",
    "tabulate", "PNG16_MAX", "check_png_header", "load_photometric", "resolve_photometric_folder", "read_mat_array",
    "read_png", "RGLBRDF",
    "load_rgl", "read_rgl", "resolve_rgl_path",
]
