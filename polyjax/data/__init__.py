"""Loaders for measured BRDF data; all return :class:`polyjax.Measurements`.

The data root is an argument (``root=``) or the environment variable ``POLYJAX_DATA``.
"""

from .._config import DATA_ENV, data_root, has_data_root
from ._curet import (
    ANISOTROPIC_SAMPLES,
    ISOTROPIC_52,
    TABLE2_SAMPLES,
    ZOOMED_DUPLICATES,
    curet_sample_names,
    load_curet,
    read_curet_geometry,
)
from ._synthetic import synthetic_default
from ._load import load

__all__ = [
    "DATA_ENV", "data_root", "has_data_root", "ANISOTROPIC_SAMPLES", "ISOTROPIC_52", "TABLE2_SAMPLES",
    "ZOOMED_DUPLICATES", "curet_sample_names", "load_curet", "read_curet_geometry", "synthetic_default", "load",
]
