"""Reproduce the paper's Tables 1-4 and Figs. 3, 5-8, and accuracy vs fit time (the same as ``polyjax reproduce``).

    POLYJAX_DATA=... python benchmarks/reproduce.py [--quick] [--out results]

Writes tables (markdown), figures (PNG, EXR), ``report.md`` and ``results.json`` to ``--out``.
"""

import sys

from polyjax._reproduce import main

if __name__ == "__main__":
    sys.exit(main())
