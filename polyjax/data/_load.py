"""One entry point for every dataset: ``load("curet:25")``, ``load("merl-nbrdf:green-latex")``,
``load("cornell:cayman")``."""

from __future__ import annotations

import os

from .._errors import UnknownNameError
from .._measurements import Measurements
from ._cornell import load_cornell
from ._curet import ISOTROPIC_52, TABLE2_SAMPLES, load_curet
from ._merl import load_merl_binary
from ._nbrdf import _is_merl_name, load_merl_nbrdf, load_nbrdf_measurements
from ._rgl import load_rgl

#: the named sets of CUReT samples: ``curet:isotropic`` (the paper's 52 isotropic samples of Figs. 6-7 and Table
#: 4, :data:`polyjax.data.ISOTROPIC_52`), ``curet:table2`` (the five of Table 2 and Fig. 3)
CURET_SETS = {"isotropic": ISOTROPIC_52, "table2": tuple(TABLE2_SAMPLES)}
#: data files given by their path alone, without a ``kind:``: their suffix names the kind (one rule for every
#: command and :func:`load`)
FILE_KINDS = {".bsdf": "rgl", ".binary": "merl"}

_KINDS = ("'curet:<sample>' (or 'curet:isotropic', 'curet:table2'), 'merl-nbrdf:<material>', "
          "'nbrdf:<zip or folder>[:<material>,...]', 'cornell:<material>', 'merl:<path to .binary>' or "
          "'rgl:<.bsdf file or name>' (a .bsdf or .binary file may be given by its path alone)")


def dataset_spec(arg: str) -> str:
    """The data set spec of a command-line argument: a bare path of a data file (``half.bsdf``, ``satin.binary``:
    :data:`FILE_KINDS`) becomes ``rgl:half.bsdf`` / ``merl:satin.binary``; anything else is returned as given."""
    s = str(arg).strip()
    kind = FILE_KINDS.get(os.path.splitext(s)[1].lower())
    if kind is None or s.lower().startswith(kind + ":"):
        return str(arg)
    return f"{kind}:{s}"


def load(spec: str, root: str | os.PathLike | None = None, **options) -> Measurements:
    """Load a dataset by name.

    Args:
        spec: ``"<kind>:<what>"``, several items separated by commas, or the path of a ``.bsdf`` or ``.binary``
            file alone (:func:`dataset_spec`):

            - ``"curet:25"``, ``"curet:25,33"``, ``"curet:quarry tile"``, ``"curet"`` (all 61 samples),
              ``"curet:isotropic"`` (the paper's 52 isotropic samples) or ``"curet:table2"`` (:data:`CURET_SETS`);
            - ``"merl-nbrdf:green-latex"``, ``"merl-nbrdf:table3"`` (the six of Table 3), ``"merl-nbrdf:all"``:
              the neural MERL fits on the MERL grid (options ``subsample``, ``seed``);
            - ``"nbrdf:<zip or folder>:<material>[,<material>...]"`` or ``"nbrdf:<zip or folder>"`` (all):
              neural BRDFs of any set in the published format on the MERL grid
              (:func:`load_nbrdf_measurements`; options ``subsample``, ``seed``); ``"nbrdf:<MERL name>"``
              is ``"merl-nbrdf:<MERL name>"``;
            - ``"cornell:cayman"`` (also ``garnet_red``, ``acryl_blue`` or a file path; option ``channels``);
            - ``"merl:/path/to/file.binary"``: a MERL ``.binary`` file (options ``subsample``, ``seed``);
            - ``"rgl:/path/to/file.bsdf"`` or ``"rgl:paper_white_rgb"`` (in ``<root>/rgl_epfl/``): an RGL-EPFL
              measured BSDF on the MERL grid (:func:`load_rgl`; options ``subsample``, ``seed``, ``clip``).
        root: data root (default ``$POLYJAX_DATA``).
        **options: passed to the loader (:func:`load_merl_nbrdf`, :func:`load_cornell`, :func:`load_merl_binary`).
    """
    kind, _, rest = dataset_spec(spec).partition(":")
    kind = kind.strip().lower()
    items = [s.strip() for s in rest.split(",") if s.strip()]
    if kind == "curet":
        if options:
            raise UnknownNameError(f"load({spec!r}): CUReT takes no options, found {sorted(options)}")
        if len(items) == 1 and items[0].lower() in CURET_SETS:
            items = list(CURET_SETS[items[0].lower()])
        return load_curet(root, items or None)
    if kind == "nbrdf" and rest.strip() and not all(_is_merl_name(i) for i in items):
        path, sep, what = rest.strip().rpartition(":")
        if not sep or not path:
            path, what = rest.strip(), ""
        names = [s.strip() for s in what.split(",") if s.strip()]
        return load_nbrdf_measurements(path, None if not names else names[0] if len(names) == 1 else names, **options)
    if kind in ("merl-nbrdf", "nbrdf", "merl_nbrdf"):
        if not items:
            raise UnknownNameError(f"dataset {spec!r}: expected 'merl-nbrdf:<material>[,<material>...]', "
                                   "'table3' or 'all'")
        return load_merl_nbrdf(items[0] if len(items) == 1 else items, root, **options)
    if kind == "cornell":
        if not items:
            raise UnknownNameError(f"dataset {spec!r}: expected 'cornell:<material or path>'")
        return load_cornell(items[0] if len(items) == 1 else items, root, **options)
    if kind == "merl":
        if not items:
            raise UnknownNameError(f"dataset {spec!r}: expected 'merl:<path to .binary>[,<path>...]'")
        return load_merl_binary(items[0] if len(items) == 1 else items, **options)
    if kind == "rgl":
        if not rest.strip():
            raise UnknownNameError(f"dataset {spec!r}: expected 'rgl:<.bsdf file or name in <root>/rgl_epfl>'")
        return load_rgl(rest.strip(), root=root, **options)
    raise UnknownNameError(f"dataset {spec!r}: expected {_KINDS}")
