"""Shared test settings.

A test skips, saying why, when something it needs is absent (BROAD, the firmware image, Xvfb …), so a
person can run the suite on any machine. `scripts/test` (and so CI) sets SPHERE_STRICT_SKIPS=1 after
building everything: there a skip means a broken build or setup, and it fails the run — unless its
reason contains "[optional]" (something this machine cannot have, such as /dev/uinput).
"""

import os

import pytest
from hypothesis import settings

STRICT = os.environ.get("SPHERE_STRICT_SKIPS") == "1"

# property tests judge results, not the machine's load: no per-example time limit (hypothesis's 200 ms
# deadline failed a decoder property test at load 9 on two cores)
settings.register_profile("sphere", deadline=None)
settings.load_profile("sphere")


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
