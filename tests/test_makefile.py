"""The Makefile's lists of tests name files that exist: a renamed test module must not silently leave
``make test-portable`` failing with "file or directory not found" (as tests/solvers/test_damage.py did)."""

import re

import pytest
from conftest import ROOT

pytestmark = pytest.mark.serial  # no MPI here: on 2 ranks each would run the same checks again


def test_the_portable_tests_exist():
    text = (ROOT / "Makefile").read_text().replace("\\\n", " ")
    listed = re.search(r"^PORTABLE_TESTS := (.*)$", text, flags=re.M).group(1).split()
    assert len(listed) > 10
    missing = [p for p in listed if not (ROOT / p).exists()]
    assert not missing, missing
