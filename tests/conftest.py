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

#: Modules whose figures are the machine's timing (motion to X pointer in ms, the X pointer's px/s and clicks, the
#: daemon bench's side-by-side speed, the AR page's frames drawn, the samples' age): marked ``timing``.
#: `scripts/test` runs the rest on several workers (pytest-xdist) and then these alone, one after another.
TIMING_MODULES = frozenset({
    "tests/e2e/test_baud_switch.py",  # the board keeping pace with the host's wall-clock waits
    "tests/e2e/test_bench_latency.py",
    "tests/e2e/test_pointer_drift_x11.py",
    "tests/e2e/test_pointer_smoothing_x11.py",
    "tests/e2e/test_mouse_x11.py",
    "tests/e2e/test_hybrid_ar.py",
    "tests/host/test_daemon_bench.py",
    "tests/host/test_sample_age.py",
})
ROOT = Path(__file__).resolve().parents[1]


def pytest_configure(config):
    config.addinivalue_line("markers", "timing: judges the machine's timing; run alone (tests/conftest.py)")
    # pytest-xdist's own mark (pytest_collection_modifyitems), known also to a pytest without the plugin
    config.addinivalue_line("markers", "xdist_group(name): the tests of one group run on one worker (pytest-xdist)")


def pytest_collection_modifyitems(config, items):
    """The timing modules marked ``timing``; every test grouped by its module, so that with pytest-xdist's
    ``--dist loadgroup`` a module's tests share one worker (its fixtures, a simulator or an X server, made once)."""
    for item in items:
        module = Path(str(item.fspath)).resolve().relative_to(ROOT).as_posix()
        if module in TIMING_MODULES:
            item.add_marker(pytest.mark.timing)
        item.add_marker(pytest.mark.xdist_group(module))


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
