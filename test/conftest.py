"""Shared pytest fixtures: where the real robot bags are."""
import os
import sys

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
REAL_DATA = os.path.normpath(os.path.join(ROOT, '..', 'shared', 'data', 'real'))

try:
    import cc_log  # noqa: F401  (a sourced workspace also provides the generated cc_log.msg)
except ImportError:
    sys.path.insert(0, os.path.join(ROOT, 'src'))


@pytest.fixture
def real_bag():
    """Return the path of a real bag in ../shared/data/real by file name; fail when it is missing."""
    def find(name):
        path = os.path.join(REAL_DATA, name)
        if not os.path.exists(path):
            pytest.fail('real data missing: %s (tests read ../shared/data/real/)' % path)
        return path
    return find
