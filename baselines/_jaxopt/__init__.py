"""The jaxopt backend of the multi-start fit (``backend="jaxopt"``) and its staged kernel, loaded on first use.

``import jaxopt`` takes about 0.25 s (it imports scipy's optimisers), half of what a warm first fit in a fresh
process may cost after ``import polyjax`` (``benchmarks/bench_latency.py``), and the default backend never uses
it: :func:`staged_kernel` (:mod:`baselines._jaxopt.staged`) is therefore imported by this face's ``__getattr__``
when a fit first asks for it (``baselines._jaxopt.staged_kernel``)."""

__all__ = ["staged_kernel"]


def __getattr__(name: str):
    if name == "staged_kernel":
        from .staged import staged_kernel  # lazy: jaxopt's import cost (module docs)

        return staged_kernel
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
