"""Paths of the simulated sessions made by tests/make_fixtures.py (ctest fixture)."""
import os
import unittest

ROOT = os.environ.get("MANIP_PY_FIXTURES") or os.path.join(os.path.dirname(__file__), "..", "..", "build",
                                                            "python_fixtures")
SESSION = os.path.join(ROOT, "session")
S_LCM = os.path.join(SESSION, "s.lcm")
S_JSON = os.path.join(SESSION, "s.json")
S_SIG = os.path.join(SESSION, "sig")
S_VAL = os.path.join(SESSION, "val", "validation.json")
GROUP = os.path.join(ROOT, "group")
GROUP_JSON = [os.path.join(GROUP, "p%d.json" % i) for i in range(1, 6)]


def require(*paths):
    missing = [p for p in paths if not os.path.exists(p)]
    if missing:
        # A missing fixture is a failure, not a skip: run the ctest fixture python:fixtures first.
        raise AssertionError("fixture missing (run ctest -R python: so python:fixtures runs first): %s" % missing)
