"""Property-based fuzzing of every loader (Hypothesis): a small valid input of each (``tests/_fuzz_problems.py``),
damaged by truncations, bit flips, huge declared sizes and values of the wrong type, loads as a valid result or
raises a :class:`polyjax.PolyjaxError`, never another exception, and allocates less than
:data:`_fuzz_problems.MEMORY_CAP` (tracemalloc) doing so.

The default tier tries :data:`DEFAULT_EXAMPLES` cases of each loader, the same ones every run (derandomized); the slow
tier (``-m slow``) :data:`SLOW_EXAMPLES` random ones. Each test prints its counts (``-s`` shows them).
"""

from __future__ import annotations

from collections import Counter

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import polyjax as pj

from _fuzz_problems import MEMORY_CAP, PROBLEMS, peak_bytes

DEFAULT_EXAMPLES = 25
SLOW_EXAMPLES = 400
TIERS = [pytest.param(DEFAULT_EXAMPLES, id="default"),
         pytest.param(SLOW_EXAMPLES, id="slow", marks=pytest.mark.slow)]


def fuzz(name: str, examples: int, folder, derandomize: bool) -> Counter:
    """Damage the valid input of loader ``name`` ``examples`` times; every outcome checked; the counts."""
    problem = PROBLEMS[name]
    folder.mkdir()
    target = problem.build(folder)
    out, _ = peak_bytes(problem.load, target)
    assert not isinstance(out, BaseException), f"the valid input of {name} does not load: {out!r}"
    files = problem.files(target)
    originals = {f: f.read_bytes() for f in files}
    counts = Counter()

    @settings(max_examples=examples, deadline=None, derandomize=derandomize, database=None,
              suppress_health_check=list(HealthCheck))
    @given(st.data())
    def case(data):
        for f, raw in originals.items():
            f.write_bytes(raw)
        f = files[data.draw(st.integers(0, len(files) - 1), label="file")]
        f.write_bytes(problem.damage(data, originals[f]))
        out, peak = peak_bytes(problem.load, target)
        if isinstance(out, BaseException) and not isinstance(out, pj.PolyjaxError):
            raise AssertionError(f"{name}: {type(out).__name__}: {out}") from out
        assert peak < MEMORY_CAP, f"{name}: {peak / 2**20:.1f} MiB allocated by one load"
        counts["PolyjaxError" if isinstance(out, BaseException) else "valid"] += 1

    case()
    print(f"fuzz {name}: {sum(counts.values())} cases, {counts['valid']} valid, {counts['PolyjaxError']} "
          "PolyjaxError, 0 other exceptions")
    return counts


@pytest.mark.parametrize("examples", TIERS)
@pytest.mark.parametrize("name", sorted(PROBLEMS))
def test_damaged_input_loads_or_raises_a_polyjax_error_within_the_memory_cap(name, examples, tmp_path):
    counts = fuzz(name, examples, tmp_path / "in", derandomize=examples == DEFAULT_EXAMPLES)
    assert sum(counts.values()) >= 1
