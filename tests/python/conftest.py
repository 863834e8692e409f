"""pytest setup for the Python module's tests (run by ctest with PYTHONPATH=<build>/python).

A test module may list tests not to run as NOT_RUN = [(test id prefix, reason), ...]; they are
reported as skipped with the reason.
"""

import pytest


def pytest_collection_modifyitems(items):
    for item in items:
        test_id = item.nodeid.split("::", 1)[-1]
        for prefix, reason in getattr(item.module, "NOT_RUN", ()):
            if test_id.startswith(prefix):
                item.add_marker(pytest.mark.skip(reason=reason))
