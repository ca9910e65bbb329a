r"""Spectral BRDF values to CIE XYZ, luminance and linear sRGB.

Convention (stated once, used by every loader):

- Colour-matching functions: CIE 1931 2-degree standard observer, tabulated at 400, 410, ..., 700 nm
  (the wavelengths of the Cornell data), embedded below.
- Illuminant: equal-energy (CIE E). A BRDF spectrum ``f(lambda)`` (1/sr) maps to
  ``X = sum f xbar / sum ybar``, ``Y = sum f ybar / sum ybar``, ``Z = sum f zbar / sum ybar`` over the
  tabulated wavelengths, so a flat spectrum of value ``c`` gives ``Y = c`` exactly (luminance in 1/sr).
- RGB: linear sRGB primaries (IEC 61966-2-1, XYZ -> RGB matrix below), followed by a diagonal white
  balance that maps the equal-energy white to ``R = G = B``: a flat spectrum of value ``c`` gives
  ``(c, c, c)`` exactly. No gamma (values stay linear, in 1/sr).
"""

from __future__ import annotations

import numpy as np

from .._errors import InputError

#: Wavelengths (nm) of :data:`CIE1931_CMF`.
CMF_WAVELENGTHS = np.arange(400, 701, 10, dtype=np.float64)

#: CIE 1931 2-degree colour-matching functions (xbar, ybar, zbar) at 400..700 nm in 10 nm steps.
CIE1931_CMF = np.array([
    [0.014310, 0.000396, 0.067850],  # 400
    [0.043510, 0.001210, 0.207400],  # 410
    [0.134380, 0.004000, 0.645600],  # 420
    [0.283900, 0.011600, 1.385600],  # 430
    [0.348280, 0.023000, 1.747060],  # 440
    [0.336200, 0.038000, 1.772110],  # 450
    [0.290800, 0.060000, 1.669200],  # 460
    [0.195360, 0.090980, 1.287640],  # 470
    [0.095640, 0.139020, 0.812950],  # 480
    [0.032010, 0.208020, 0.465180],  # 490
    [0.004900, 0.323000, 0.272000],  # 500
    [0.009300, 0.503000, 0.158200],  # 510
    [0.063270, 0.710000, 0.078250],  # 520
    [0.165500, 0.862000, 0.042160],  # 530
    [0.290400, 0.954000, 0.020300],  # 540
    [0.433450, 0.994950, 0.008750],  # 550
    [0.594500, 0.995000, 0.003900],  # 560
    [0.762100, 0.952000, 0.002100],  # 570
    [0.916300, 0.870000, 0.001650],  # 580
    [1.026300, 0.757000, 0.001100],  # 590
    [1.062200, 0.631000, 0.000800],  # 600
    [1.002600, 0.503000, 0.000340],  # 610
    [0.854450, 0.381000, 0.000190],  # 620
    [0.642400, 0.265000, 0.000050],  # 630
    [0.447900, 0.175000, 0.000020],  # 640
    [0.283500, 0.107000, 0.000000],  # 650
    [0.164900, 0.061000, 0.000000],  # 660
    [0.087400, 0.032000, 0.000000],  # 670
    [0.046770, 0.017000, 0.000000],  # 680
    [0.022700, 0.008210, 0.000000],  # 690
    [0.011359, 0.004102, 0.000000],  # 700
])

#: XYZ -> linear sRGB (D65 primaries), IEC 61966-2-1.
XYZ_TO_SRGB = np.array([
    [3.2406, -1.5372, -0.4986],
    [-0.9689, 1.8758, 0.0415],
    [0.0557, -0.2040, 1.0570],
])


def _cmf_at(wavelengths) -> np.ndarray:
    wl = np.asarray(wavelengths, dtype=np.float64)
    if wl.ndim != 1 or wl.size < 2 or np.any(np.diff(wl) <= 0):
        raise InputError(f"wavelengths: expected increasing nm values, found {wl}")
    if wl[0] < CMF_WAVELENGTHS[0] - 1e-9 or wl[-1] > CMF_WAVELENGTHS[-1] + 1e-9:
        raise InputError(f"wavelengths: expected values within 400..700 nm (the embedded CIE table), "
                         f"found {wl[0]}..{wl[-1]}")
    return np.stack([np.interp(wl, CMF_WAVELENGTHS, CIE1931_CMF[:, c]) for c in range(3)], axis=-1)


def spectral_to_xyz(spectra, wavelengths) -> np.ndarray:
    """``(..., n_wl)`` spectra -> ``(..., 3)`` CIE XYZ under the equal-energy illuminant, ``Y(flat 1) = 1``.

    Wavelengths off the 10 nm grid use linearly interpolated colour-matching functions.
    """
    cmf = _cmf_at(wavelengths)
    s = np.asarray(spectra, dtype=np.float64)
    if s.shape[-1] != cmf.shape[0]:
        raise InputError(f"spectra: expected {cmf.shape[0]} values per spectrum (one per wavelength), "
                         f"found {s.shape[-1]}")
    return s @ cmf / cmf[:, 1].sum()


def xyz_to_rgb_matrix(wavelengths=CMF_WAVELENGTHS) -> np.ndarray:
    """XYZ -> white-balanced linear sRGB: ``XYZ_TO_SRGB`` rows scaled so that the equal-energy white
    (XYZ of a flat spectrum of 1 at these wavelengths) maps to ``(1, 1, 1)``."""
    white = spectral_to_xyz(np.ones(len(wavelengths)), wavelengths)
    rgb_white = XYZ_TO_SRGB @ white
    return XYZ_TO_SRGB / rgb_white[:, None]


def spectral_to_rgb(spectra, wavelengths) -> np.ndarray:
    """``(..., n_wl)`` spectra -> ``(..., 3)`` white-balanced linear sRGB (module docstring)."""
    return spectral_to_xyz(spectra, wavelengths) @ xyz_to_rgb_matrix(wavelengths).T


def spectral_to_luminance(spectra, wavelengths) -> np.ndarray:
    """``(..., n_wl)`` spectra -> ``(...)`` CIE Y (equal-energy illuminant, ``Y(flat 1) = 1``)."""
    return spectral_to_xyz(spectra, wavelengths)[..., 1]
