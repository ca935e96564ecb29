"""The estimator study's sentence on its adapted series' reference (issue 32, item 17): it read "its own error is
about 1.2e-05 with P2's C, 1.2e-05 with P2's" (a hard-coded 1.6e-3 for the second); now it says what it means."""

import json
import re

import pytest
from conftest import ROOT

from studies.estimator import markdown

pytestmark = pytest.mark.serial  # no MPI here: on 2 ranks each would run the same checks again


def test_the_reference_sentence_says_what_its_own_error_is_and_against_what():
    result = json.loads((ROOT / "benchmarks" / "results" / "estimator.json").read_text())
    text = markdown(result)
    sentences = re.findall(r"Reference: P2 on the last mesh[^\n]*", text)
    assert len(sentences) == len(result["adapted"]) == 2
    c2 = [r for r in result["runs"] if r["degree"] == 2][-1]["C"]  # P2's C on the finest uniform P2 mesh
    for series, sentence in zip(result["adapted"], sentences):
        assert "with P2's)" not in sentence and "with P1's C" not in sentence
        own = series["reference"]["eta"] * c2
        last = series["runs"][-1]["error"]
        assert f"P2's C = error / eta = {c2:.3e}" in sentence
        assert f"its own error at about {own:.1e}, {100 * own / last:.1f} % of the last adapted run's error" in sentence
    assert "refined uniformly once" in sentences[0] and "refined uniformly twice" in sentences[1]


def test_the_note_uses_the_p2_constant_given_whatever_the_series_degree():
    from studies.estimator import reference_note

    series = {"degree": 1, "reference": {"refinements": 3, "dofs": 1000, "eta": 2.0e-2},
              "runs": [{"dofs": 50, "error": 1.0e-2, "C": 4.0e-3}, {"dofs": 100, "error": 5.0e-3, "C": 4.0e-3}]}
    note = reference_note(series, [{"dofs": 80, "C": 2.0e-3}])
    assert "refined uniformly 3 times (1000 dofs)" in note and "(measured at 80 dofs)" in note
    assert f"about {2.0e-2 * 2.0e-3:.1e}" in note and "0.8 % of the last adapted run's error 5.000e-03" in note
