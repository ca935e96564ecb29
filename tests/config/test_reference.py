"""The scene-key reference (solver/config/reference.py) documents every key and is what docs/reference/scene.md holds."""

import dataclasses

import pytest
from conftest import ROOT

from solver.config import boundary, reference
from solver.config.scene import SECTIONS

pytestmark = pytest.mark.serial  # no MPI in this layer: on 2 ranks each would run the same checks again


def test_every_config_field_has_a_line():
    """A field added to a section's dataclass without a MEANING line (or a line left for a removed key) fails here."""
    documented = {dotted for dotted, _ in reference.fields()}
    missing = sorted(documented - set(reference.MEANING))
    stale = sorted(set(reference.MEANING) - documented)
    assert not missing, f"scene keys without a line in solver/config/reference.py MEANING: {missing}"
    assert not stale, f"MEANING lines for keys that are gone: {stale}"
    assert {s.key for s in SECTIONS} == {d.split(".")[0] for d in documented}
    assert set(reference.CHOICES) <= documented


def test_boundary_keys_are_the_toml_keys():
    """The boundary rows are the keys a scene file takes; the dataclass's other fields are named in DERIVED."""
    fields = {f.name for f in dataclasses.fields(boundary.BoundaryConfig)}
    rows = {d.rsplit(".", 1)[1] for d, _ in reference.fields() if d.startswith("boundary.")}
    assert rows == set(boundary._KEYS)
    assert fields == rows | set(reference.DERIVED)


def test_a_missing_line_fails(monkeypatch):
    """keys() refuses a key without a meaning (what the test above guards against)."""
    monkeypatch.delitem(reference.MEANING, "time.k")
    with pytest.raises(KeyError):
        reference.keys()


def test_page_is_generated():
    """docs/reference/scene.md is markdown() (regenerate: python -m solver.config.reference > docs/reference/scene.md)."""
    assert (ROOT / "docs" / "reference" / "scene.md").read_text() == reference.markdown()
