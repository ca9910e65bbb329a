"""The reproduction of Ozturk et al. 2008: the paper's numbers, experiments, figures and the report.

Run it as ``python benchmarks/reproduce.py [--quick] --out DIR``. Only the public APIs of ``polyjax`` and
``baselines`` are used.
"""
