"""Shared test settings.

A test skips, saying why, when something it needs is absent (BROAD, the firmware image, Xvfb …), so a
person can run the suite on any machine. `scripts/test` (and so CI) sets SPHERE_STRICT_SKIPS=1 after
building everything: there a skip means a broken build or setup, and it fails the run — unless its
reason contains "[optional]" (something this machine cannot have, such as /dev/uinput).
"""

import os
from pathlib import Path

import pytest
from hypothesis import settings

STRICT = os.environ.get("SPHERE_STRICT_SKIPS") == "1"

# property tests judge results, not the machine's load: no per-example time limit (hypothesis's 200 ms
# deadline failed a decoder property test at load 9 on two cores)
settings.register_profile("sphere", deadline=None)
settings.load_profile("sphere")

#: Modules whose figures are the machine's timing (motion to X pointer in ms, the X pointer's px/s, the daemon bench's
#: side-by-side speed, the AR page's frames drawn, the samples' age): `scripts/test` runs the suite on several
#: workers (pytest-xdist, --dist loadgroup), and these run one after another on one of them, never two at once.
TIMING_MODULES = frozenset({
    "tests/e2e/test_bench_latency.py",
    "tests/e2e/test_pointer_drift_x11.py",
    "tests/e2e/test_pointer_smoothing_x11.py",
    "tests/e2e/test_hybrid_ar.py",
    "tests/host/test_daemon_bench.py",
    "tests/host/test_sample_age.py",
})
ROOT = Path(__file__).resolve().parents[1]


def pytest_collection_modifyitems(config, items):
    """Each module's tests on one worker (its module fixtures, a simulator or an X server, made once), the
    timing modules together on one."""
    for item in items:
        module = Path(str(item.fspath)).resolve().relative_to(ROOT).as_posix()
        item.add_marker(pytest.mark.xdist_group("timing" if module in TIMING_MODULES else module))


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item, call):
    outcome = yield
    report = outcome.get_result()
    if not (STRICT and report.skipped) or hasattr(report, "wasxfail"):  # an expected failure is no skip
        return
    reason = str(call.excinfo.value) if call.excinfo is not None else str(report.longrepr)
    if "[optional]" in reason:
        return
    report.outcome = "failed"
    report.longrepr = f"skipped in a strict run (SPHERE_STRICT_SKIPS=1, set by scripts/test): {reason}"
