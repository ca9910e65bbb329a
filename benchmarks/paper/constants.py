"""Every number quoted from Ozturk, Kurt, Bilgili, Gungor, "Linear approximation of Bidirectional Reflectance
Distribution Functions", Computers & Graphics 32 (2008) 149-158, and the run configurations taken from it."""

from __future__ import annotations

#: Table 1: L2 of the Lafortune-variable polynomial for p = 1..6.
PAPER_TABLE1: dict[str, tuple[float, ...]] = {
    "Quarry Tile": (0.0324, 0.0205, 0.0142, 0.0116, 0.0106, 0.0093),
    "Cayman lacquer": (2.1983, 2.1981, 2.1981, 2.1979, 2.1972, 2.1953),
}

#: Table 2: L2 on Felt (1), Orange peel (55), Quarry tile (25), Slate_a (33), Slate_b (34).
PAPER_TABLE2: dict[str, tuple[float, ...]] = {
    "ashikhmin-shirley": (0.0190, 0.0217, 0.0165, 0.0121, 0.0223),
    "blinn-phong": (0.0518, 0.0626, 0.0369, 0.0196, 0.0586),
    "cook-torrance": (0.0229, 0.0213, 0.0136, 0.0107, 0.0236),
    "lafortune": (0.0170, 0.0245, 0.0117, 0.0070, 0.0184),
    "oren-nayar": (0.0571, 0.0740, 0.0429, 0.0249, 0.0711),
    "ward": (0.0385, 0.0420, 0.0241, 0.0124, 0.0383),
    "ward-duer": (0.0238, 0.0219, 0.0137, 0.0109, 0.0243),
    "zernike": (0.0087, 0.0126, 0.0069, 0.0059, 0.0068),
    "poly:ashikhmin-shirley:5": (0.0090, 0.0206, 0.0098, 0.0063, 0.0114),
    "poly:lafortune:7": (0.0126, 0.0227, 0.0093, 0.0062, 0.0165),
    "poly:ward:7": (0.0228, 0.0277, 0.0122, 0.0092, 0.0266),
}
#: The CUReT sample numbers of Table 2's columns.
TABLE2_IDS: tuple[int, ...] = (1, 55, 25, 33, 34)

#: Table 3: (L2, PSNR dB) on beige-fabric, blue-metallic-paint, dark-blue-paint, green-latex, orange-paint,
#: yellow-plastic (the order of polyjax.data.TABLE3_MATERIALS).
PAPER_TABLE3: dict[str, tuple[tuple[float, float], ...]] = {
    "ashikhmin-shirley": (
        (0.0053, 46.043), (0.0150, 39.043), (0.0043, 42.330), (0.0040, 43.286), (0.0038, 46.710), (0.0071, 39.321)),
    "blinn-phong": (
        (0.0104, 37.683), (0.0228, 31.570), (0.0109, 34.671), (0.0064, 38.841), (0.0100, 39.573), (0.0143, 36.288)),
    "cook-torrance": (
        (0.0080, 42.629), (0.0172, 39.589), (0.0035, 43.425), (0.0037, 43.255), (0.0037, 46.789), (0.0068, 39.544)),
    "lafortune": (
        (0.0075, 42.113), (0.0132, 38.099), (0.0056, 42.353), (0.0036, 44.434), (0.0061, 45.504), (0.0086, 39.709)),
    "oren-nayar": (
        (0.0105, 37.706), (0.0540, 26.654), (0.0129, 33.120), (0.0076, 38.507), (0.0119, 38.228), (0.0153, 35.654)),
    "ward": (
        (0.0101, 38.055), (0.0146, 34.977), (0.0091, 36.824), (0.0052, 40.540), (0.0085, 41.683), (0.0130, 36.976)),
    "ward-duer": (
        (0.0093, 38.563), (0.0171, 38.899), (0.0056, 39.619), (0.0037, 43.249), (0.0059, 41.680), (0.0103, 37.663)),
    "poly:ashikhmin-shirley:3": (
        (0.0038, 48.104), (0.0331, 34.291), (0.0064, 42.514), (0.0029, 47.707), (0.0049, 47.429), (0.0082, 43.864)),
    "poly:lafortune:5": (
        (0.0056, 45.083), (0.0314, 35.535), (0.0060, 42.472), (0.0029, 46.507), (0.0049, 47.244), (0.0089, 41.809)),
    "poly:ward:5": (
        (0.0064, 45.574), (0.0347, 31.333), (0.0040, 41.873), (0.0026, 49.557), (0.0039, 45.523), (0.0061, 43.561)),
}

#: Table 4: average fitting time (s) per material, 52 isotropic CUReT samples, Pentium D 2.66 GHz, 2 GB.
PAPER_TABLE4: dict[str, float] = {
    "ashikhmin-shirley": 0.33175, "blinn-phong": 0.38900, "cook-torrance": 0.34725, "lafortune": 0.36540,
    "oren-nayar": 0.15596, "ward": 0.29025, "ward-duer": 0.26925, "poly:ashikhmin-shirley:5": 0.01567,
    "poly:lafortune:7": 0.01565, "poly:ward:7": 0.01565,
}

#: Table 4's time per polynomial fit (s), the figure ``bench_fit.py`` compares with.
PAPER_SECONDS_PER_POLY_FIT: float = PAPER_TABLE4["poly:ashikhmin-shirley:5"]

#: Table 4 restricted to the nonlinear models.
PAPER_NONLINEAR_SECONDS: dict[str, float] = {k: t for k, t in PAPER_TABLE4.items() if not k.startswith("poly:")}

#: Section 6 / Fig. 6: in how many of the 52 CUReT samples each polynomial model has the lowest L2
#: of it and the seven nonlinear models.
PAPER_LOWEST_COUNTS: dict[str, int] = {"poly:ashikhmin-shirley:5": 45, "poly:lafortune:7": 40, "poly:ward:7": 23}

#: The variable sets of the paper's polynomial models.
VARIABLE_SETS: tuple[str, ...] = ("ashikhmin-shirley", "lafortune", "ward")
#: (variables, p) of Tables 2 and 4, Figs. 3 and 6 (CUReT).
CURET_POLY: tuple[tuple[str, int], ...] = (("ashikhmin-shirley", 5), ("lafortune", 7), ("ward", 7))
#: (variables, p) of Table 3, Figs. 4 and 5 (MERL).
MERL_POLY: tuple[tuple[str, int], ...] = (("ashikhmin-shirley", 3), ("lafortune", 5), ("ward", 5))
#: (variables, p) of Fig. 7: the linear models on CUReT.
FIG7_POLY: tuple[tuple[str, int], ...] = (("lafortune", 2), ("lafortune", 8))
