"""CI's slow tier: ``python -m pytest -q -m slow``, then, when every failure is a test worker that died, those tests
once more, each file in a fresh process. Any other failure, or a crashed test that fails again, fails the run; a run
whose report is missing fails too.

The crashes seen in this tier (a segmentation fault in XLA's ``backend_compile_and_load`` after a worker had run many
tests) were a worker reaching the kernel's limit on memory maps with its compiled programs; ``tests/conftest.py`` now
empties JAX's caches well before it. The second chance stays for a worker lost otherwise."""

import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

REPORT = Path(".ci/slow-tier.xml")


def failures(report: Path) -> list[tuple[str, str]]:
    """``(test id, message)`` of every failed or erroring test of a JUnit report."""
    out = []
    for case in ET.parse(report).iter("testcase"):
        for child in case:
            if child.tag in ("failure", "error"):
                file = case.get("classname", "").replace(".", "/") + ".py"
                out.append((f"{file}::{case.get('name')}", child.get("message", "")))
    return out


def main() -> int:
    REPORT.unlink(missing_ok=True)
    # whole tests handed out (--dist load), not whole files: pytest-xdist's file scheduler stops the session with an
    # INTERNALERROR when it replaces a crashed worker (pytest-xdist issues 1189 and 1362)
    status = subprocess.call([sys.executable, "-m", "pytest", "-q", "-m", "slow", "--dist", "load",
                              f"--junitxml={REPORT}"])
    if status == 0:
        return 0
    if status != 1 or not REPORT.is_file():
        print(f"slow tier: pytest exited {status} without a complete report", flush=True)
        return status or 1
    failed = failures(REPORT)
    crashed = [test for test, message in failed if "crashed while running" in message]
    if not crashed or len(crashed) != len(failed):
        return 1
    print(f"slow tier: {len(crashed)} test(s) lost with a crashed worker, run again in a fresh process: "
          + ", ".join(crashed), flush=True)
    return subprocess.call([sys.executable, "-m", "pytest", "-q", "-n", "0", "-m", "", *crashed])


if __name__ == "__main__":
    sys.exit(main())
