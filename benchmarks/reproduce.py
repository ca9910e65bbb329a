"""Reproduce the paper's Tables 1-4 and Figs. 3, 5-8, and accuracy vs fit time.

    POLYJAX_DATA=... python benchmarks/reproduce.py [--quick] [--out results]

Writes tables (markdown), figures (PNG, EXR), ``report.md`` and ``results.json`` to ``--out``. The code is in
``benchmarks/paper/`` (constants, experiments, figures, report, run).
"""

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the repository root: `benchmarks` as a package

from benchmarks.paper.run import main  # noqa: E402

if __name__ == "__main__":
    sys.exit(main())
