"""Test configuration: float64 once per process, and the measured-data root.

In CI (``CI`` set) a missing data root is a failure, not a skip.
"""

import os
import sys
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)
# the command line turns JAX's persistent compilation cache on; tests that call it in-process must not write into
# the user's cache folder (tests of the cache set their own folder)
os.environ.setdefault("POLYJAX_CACHE", "off")

# the repository root, for the reference fits and the paper's numbers shared with the benchmarks
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import pytest  # noqa: E402

from polyjax import DATA_ENV, has_data_root  # noqa: E402


def pytest_collection_modifyitems(config, items):
    if has_data_root():
        return
    if os.environ.get("CI"):
        raise pytest.UsageError(
            f"CI: the measured data root is missing; set {DATA_ENV} to the folder holding curet/, cornell/, "
            "nbrdf_sztrajman2021/ (the data tests must run in CI, not be skipped)"
        )
    skip = pytest.mark.skip(reason=f"no data root (set {DATA_ENV})")
    for item in items:
        if "data" in item.keywords:
            item.add_marker(skip)


@pytest.fixture(scope="session")
def data_root():
    from polyjax import data_root as _root

    return _root()
