"""Every in-process memo of polyjax, in one place: loaders record what they made, fits ask here.

- :class:`GridMemo`: a loader's grid arrays by their arguments (the MERL grid: the same device arrays for every file
  on a grid), computed at most once, possibly in a background thread;
- the unit directions of the last concrete pair of direction arrays (:func:`remember_unit_directions`,
  :func:`known_unit_directions`): a grid's million directions normalised once, not once per fit;
- the names of arrays whose content a loader made from its own code (:func:`remember_content`): keys of kept
  geometries use the name instead of a checksum of the bytes (:mod:`polyjax._cache.keys`);
- the geometry of the last streamed fit (:func:`remember_geometry`, :func:`remembered_geometry`).

Arrays are found by identity (weak references: an entry is forgotten with its arrays) and only concrete ones are
kept. :func:`forget_all` empties every memo (as a fresh process).
"""

from __future__ import annotations

import concurrent.futures
import functools
import threading
import weakref

import jax
import numpy as np

from .._arrays import is_concrete


class GridMemo:
    """A per-process memo of a grid function of hashable arguments (``lru_cache``'s role: the same arrays for every
    file on a grid), whose value may also be computed in a background thread (:meth:`start`): a call while that
    computation is under way waits for it instead of doing the work again. The oldest of more than ``maxsize``
    values is dropped; :meth:`cache_clear` forgets every value (as a fresh process)."""

    def __init__(self, fn, maxsize: int):
        functools.update_wrapper(self, fn)
        self._fn, self._maxsize = fn, maxsize
        self._futures: dict = {}
        self._lock = threading.Lock()
        _GRID_MEMOS.append(self)

    def __call__(self, *args):
        with self._lock:
            fut = self._futures.get(args)
            mine = fut is None
            if mine:
                fut = self._futures[args] = concurrent.futures.Future()
                done = [k for k, f in self._futures.items() if f.done()]
                for k in done[: max(0, len(self._futures) - self._maxsize)]:
                    del self._futures[k]
        if not mine:
            return fut.result()
        try:
            value = self._fn(*args)
        except BaseException as e:
            with self._lock:
                self._futures.pop(args, None)
            fut.set_exception(e)
            raise
        fut.set_result(value)
        return value

    def start(self, *args) -> None:
        """Compute the value of ``args`` in a daemon thread unless it is known or under way (numpy releases the
        interpreter lock in its array loops, so the work runs beside the caller's, e.g. a file being read). An
        error there is raised again by the caller's own call."""
        with self._lock:
            if args in self._futures:
                return

        def run():
            try:
                self(*args)
            except BaseException:  # noqa: BLE001 - the caller's own call raises it
                pass

        threading.Thread(target=run, name=f"polyjax-{self._fn.__name__}", daemon=True).start()

    def cache_clear(self) -> None:
        with self._lock:
            self._futures.clear()


_GRID_MEMOS: list[GridMemo] = []


def grid_memo(maxsize: int):
    """Decorator: the function memoised by a :class:`GridMemo` of ``maxsize`` values."""
    return lambda fn: GridMemo(fn, maxsize)


_UNIT_MEMO: dict = {}


def remember_unit_directions(u, v, unit) -> None:
    """Record that ``unit``, a tuple ``(u, v, valid)``, is what normalising the concrete device arrays ``u``, ``v``
    gives (a loader that builds a grid of unit directions from angles passes them as they are; a fit records what it
    computed). Replaces the pair remembered before."""
    try:
        _UNIT_MEMO["pair"] = (weakref.ref(u), weakref.ref(v), unit)
    except TypeError:  # an array type without weak references: not remembered
        _UNIT_MEMO.pop("pair", None)


def known_unit_directions(u, v):
    """The ``(u, v, valid)`` :func:`remember_unit_directions` recorded for these very arrays, or None."""
    hit = _UNIT_MEMO.get("pair")
    if hit is not None and hit[0]() is u and hit[1]() is v:
        return hit[2]
    return None


_CONTENT: dict = {}


def remember_content(a, what: str) -> None:
    """Record that the device array ``a`` holds what ``what`` names, a deterministic function of polyjax's code (its
    source files are in every key), e.g. the MERL loader's grid directions ``"merl-grid:(90, 90, 180):float64:u"``:
    its fingerprint is then that name instead of a CRC of its bytes. Found by identity, forgotten with the array."""
    key = id(a)

    def forget(ref):
        if _CONTENT.get(key, (None,))[0] is ref:
            del _CONTENT[key]

    try:
        _CONTENT[key] = (weakref.ref(a, forget), what)
    except TypeError:  # no weak references: fingerprinted by its bytes
        pass


def content_name(a) -> str | None:
    """The name :func:`remember_content` gave ``a``, or None."""
    hit = _CONTENT.get(id(a))
    if hit is not None and hit[0]() is a:
        return hit[1]
    return None


_GEOMETRY_MEMO: dict = {}


def _geometry_key(degrees, static):
    return (tuple(int(d) for d in degrees), tuple(sorted(static.items())))


def remembered_geometry(inp, degrees, static):
    """The geometry :func:`remember_geometry` kept for the same samples (the same direction arrays by identity,
    equal weights and mask) and options, or None."""
    hit = _GEOMETRY_MEMO.get("last")
    if (hit is not None and hit["key"] == _geometry_key(degrees, static) and hit["u"]() is inp.u
            and hit["v"]() is inp.v and _same(hit["w"], inp.weights) and _same(hit["m"], inp.mask)):
        return hit["geo"]
    return None


def _same(kept, a) -> bool:
    return kept is a or np.array_equal(np.asarray(kept), np.asarray(a))


def remember_geometry(inp, degrees, static, geo) -> None:
    """Keep ``geo`` for the next fit on the same samples and options: one entry, the last one (its weights and mask
    kept as they are when they are JAX arrays, which never change, else copied)."""
    if not is_concrete(geo):
        return
    keep = lambda a: a if isinstance(a, jax.Array) else np.array(a)  # noqa: E731
    try:
        _GEOMETRY_MEMO["last"] = dict(key=_geometry_key(degrees, static), u=weakref.ref(inp.u),
                                      v=weakref.ref(inp.v), w=keep(inp.weights), m=keep(inp.mask), geo=geo)
    except TypeError:  # arrays without weak references: not remembered
        _GEOMETRY_MEMO.pop("last", None)


def forget_all() -> None:
    """Empty every memo of this module (the state of a fresh process)."""
    for m in _GRID_MEMOS:
        m.cache_clear()
    _UNIT_MEMO.clear()
    _CONTENT.clear()
    _GEOMETRY_MEMO.clear()
