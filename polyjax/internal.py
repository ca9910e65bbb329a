"""polyjax for extension packages: what a package that adds fitters or kinds of saved model builds on.

Public, but not the user's API (``polyjax.__all__``): ``baselines`` is built on exactly these and on the public API,
and imports nothing private of polyjax; another extension package can do the same. The names are kept stable as
the user API is, but they follow polyjax's internals, so their arguments may grow with them.

- inputs: :func:`prepare_inputs` (the checks and flattening every fitter shares, ``docs/conventions.md``) and
  :class:`PreparedInputs`; :func:`check_parameter_count` (no interpolating fits); :func:`fit_weights` (the weights
  of equation (11));
- tracing: :func:`is_traced`, :func:`is_concrete` (a check made eagerly only, a memo kept only for concrete arrays);
- arrays: :func:`device_array` (host data to the device, no compiled program), :func:`cast_concrete` (a concrete
  array cast on the host, no compiled program): a fitter's or a model's eager steps without programs of their own;
- solves: :data:`TALL_ROWS` (the rows from which :func:`polyjax.weighted_lstsq` factorises by CholeskyQR2: a
  fitter, or a check of one, that sizes a problem for that path);
- results: :func:`raise_on_status` (``throw=`` of every fitter), :func:`result_message`, :func:`status_warnings`;
- LAPACK: :func:`one_lapack_thread` (decorate a public fitter: jaxlib's LAPACK library limited before it runs);
- Ctrl-C: :func:`check_interrupt` (a long loop calls it between its blocks), :class:`Interrupted` (what it raises),
  :func:`install_interrupt_handler` (the command line's SIGINT handling, for a command of one's own);
- saved models: :class:`ModelKind`, :func:`module_kind`, :func:`register_model_kind`, :func:`model_kinds`,
  :func:`kind_named`, :func:`kind_of`, :func:`fitter_for` (``polyjax.save_model``/``load_model`` and
  ``polyjax fit --model`` find other packages' models through them);
- data: :func:`data_file`, :func:`configured_data_root` (files below the data root); :func:`grid_memo` (a loader's
  per-process memo of arrays made from a grid's arguments, computed once, possibly in a background thread, as the
  MERL loader's grid), :func:`forget_memos` (every in-process memo forgotten: the state of a fresh process, for
  measuring or checking what a first call does);
- compact models: :data:`COMPACT_FAMILIES` (the families of compact models, by name: ``configs``, ``n_numbers``,
  ``fit``, ``evaluate``), :class:`CompactBasisFamily` (the learned-basis family on a basis of one's own, e.g. one
  learned without the material it fits), :class:`CompactSkewFamily` (the same with a non-reciprocal part),
  :class:`CompactSharedFamily` (one shape for the three channels on such a basis), :class:`CompactSparseFamily`
  (the same, its terms chosen per material from a dictionary; :func:`compact_select_columns` its greedy selection,
  :func:`compact_pack_mask` and :func:`compact_unpack_mask` the mask's stored numbers),
  :func:`fit_compact_family` (one family's configuration fitted, no choice:
  benchmarks, checks), :func:`choose_compact` (:func:`polyjax.fit_compact`'s choice among family objects of one's
  own, e.g. a basis learned without the material; a :class:`CompactChoice`), :func:`compact_fold_ids` (the
  fold of each sample in its cross-validation), :func:`compact_fold_parts` (the folds as index arrays),
  :func:`compact_choice_order` (the order of the refits: ties within :data:`COMPACT_TIE` by the other metric);
- saved programs: :data:`SAVED_PROGRAMS_ENV`, :data:`SAVED_PROGRAMS_FOLDER`, :func:`program_key`,
  :func:`source_stamp`, :func:`load_lapack_kernels`, :func:`cache_disabled_by_env`, :func:`compile_for_saving`,
  :func:`save_program`, :func:`load_program` (a fitter keeping its compiled executable beside the compilation cache,
  as ``polyjax fit`` does: no pickle, a digest checked, nothing loaded from a folder others may write);
- files: :func:`write_atomically`, :func:`write_bytes_atomically` (every output written whole or not at all),
  :func:`check_output_path` (an output path checked before any work); :func:`make_cache_folder` (a cache folder made
  polyjax's own: mode ``0700`` and the marker that lets the size cap and ``polyjax cache clear`` touch its entries).
"""

from ._arrays import cast_concrete, device_array, is_concrete, is_traced
from ._cache.compilation import cache_disabled_by_env, compile_for_saving
from ._cache.keys import program_key, source_stamp
from ._cache.memo import forget_all as forget_memos
from ._cache.memo import grid_memo
from ._cache.programs import load_lapack_kernels, load_program, save_program
from ._compact.families import FAMILIES as COMPACT_FAMILIES
from ._compact.families import BasisFamily as CompactBasisFamily
from ._compact.families import SharedShapeFamily as CompactSharedFamily
from ._compact.families import SkewBasisFamily as CompactSkewFamily
from ._compact.families import SparseShapeFamily as CompactSparseFamily
from ._compact.families.sparse import pack as compact_pack_mask
from ._compact.families.sparse import select as compact_select_columns
from ._compact.families.sparse import unpack as compact_unpack_mask
from ._compact.fit import Choice as CompactChoice
from ._compact.fit import choose_compact, fit_compact_family
from ._compact.select import TIE as COMPACT_TIE
from ._compact.select import choice_order as compact_choice_order
from ._compact.select import fold_ids as compact_fold_ids
from ._compact.select import fold_parts as compact_fold_parts
from ._config import configured_data_root, data_file
from ._files import check_output_path, make_cache_folder, write_atomically, write_bytes_atomically
from ._fit.saved import ENV as SAVED_PROGRAMS_ENV
from ._fit.saved import FOLDER as SAVED_PROGRAMS_FOLDER
from ._inputs import PreparedInputs, check_parameter_count, prepare_inputs
from ._io import ModelKind, fitter_for, kind_named, kind_of, model_kinds, module_kind, register_model_kind
from ._metrics import fit_weights
from ._results import message as result_message
from ._results import raise_on_status, status_warnings
from ._run.interrupt import Interrupted, check_interrupt
from ._run.interrupt import install as install_interrupt_handler
from ._solve.lstsq import TALL_ROWS
from ._solve.threads import one_lapack_thread

__all__ = [
    "SAVED_PROGRAMS_ENV", "SAVED_PROGRAMS_FOLDER", "cache_disabled_by_env", "compile_for_saving", "load_lapack_kernels",
    "load_program", "save_program",
    "program_key",
    "source_stamp",
    "ModelKind", "PreparedInputs", "check_parameter_count", "configured_data_root", "data_file", "device_array",
    "fit_weights", "fitter_for", "is_concrete", "is_traced", "kind_named", "kind_of", "model_kinds", "module_kind",
    "one_lapack_thread", "prepare_inputs", "raise_on_status", "register_model_kind", "result_message",
    "status_warnings",
    "TALL_ROWS", "cast_concrete", "forget_memos", "grid_memo",
    "check_output_path", "make_cache_folder", "write_atomically", "write_bytes_atomically",
    "COMPACT_FAMILIES", "CompactBasisFamily", "CompactChoice", "CompactSharedFamily", "CompactSkewFamily",
    "CompactSparseFamily", "compact_pack_mask", "compact_select_columns", "compact_unpack_mask",
    "choose_compact",
    "compact_fold_ids", "compact_fold_parts", "fit_compact_family", "COMPACT_TIE", "compact_choice_order",
    "Interrupted", "check_interrupt", "install_interrupt_handler",
]
