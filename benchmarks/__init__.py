"""Benchmarks and the paper's reproduction (not part of the installed package).

A package so that the tests can share :mod:`benchmarks.paper.references` (the numpy and scipy reference fits)
and :mod:`benchmarks.paper.constants` (the paper's numbers). The scripts put the repository root on ``sys.path``.
"""
