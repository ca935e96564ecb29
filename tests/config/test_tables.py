"""Tables as data: every table key reads a CSV file ({file, columns}) as it reads the same rows inline, errors name
the file, the line and the column, and the resolved scene refers to a copy of the file (solver/config/tables.py)."""

import tomllib

import numpy as np
import pytest

from solver.config import ConfigError, dumps, from_dict, load
from solver.config.scene import dumps_referring
from solver.config.tables import DataTable, write_copy
from solver.config.tomlread import BIG
from solver.config.tomlread import loads as fast_loads

pytestmark = pytest.mark.serial  # no MPI in this layer: on 2 ranks each would run the same checks again

LEFT = {"role": "clamped"}


def scene(**bottom) -> dict:
    return {"boundary": {"left": LEFT, "bottom": {"role": "contact", **bottom}}}


def test_a_gap_table_from_a_file_equals_the_same_rows_inline(tmp_path):
    (tmp_path / "profile.csv").write_text("# scanned profile\nx, depth, g\n\n0.0, 9, 0.0\n0.5,9,0.01\n# a comment\n1.0,9,0.04\n")
    by_name = from_dict(scene(gap={"file": "profile.csv", "columns": ["x", "g"]}), base=tmp_path)
    by_number = from_dict(scene(gap={"file": str(tmp_path / "profile.csv"), "columns": [1, 3]}))
    inline = from_dict(scene(gap=[[0.0, 0.0], [0.5, 0.01], [1.0, 0.04]]))
    assert by_name.contact[0].gap_table == by_number.contact[0].gap_table == inline.contact[0].gap_table
    assert by_name.contact[0] == inline.contact[0] and isinstance(by_name.contact[0].gap_table, DataTable)
    assert by_name.contact[0].gap_table.labels == ("x", "g")


@pytest.mark.parametrize("text, columns, line, words", [
    ("s,g\n0,0\n0.5,abc\n", None, 3, "column 2 (g) must be a number"),
    ("s,g\n0,0\n0.5,0.1,7\n", None, 3, "has 3 columns where the file has 2"),
    ("0,0\n0.5,nan\n", None, 2, "column 2 must be a finite number"),
    ("# c\ns,g\n0,0\n\n0.5,0\n0.5,0.1\n", None, 6, "the coordinates s must increase strictly"),
])
def test_errors_name_the_file_line_and_column(tmp_path, text, columns, line, words):
    (tmp_path / "p.csv").write_text(text)
    with pytest.raises(ConfigError) as exc:
        from_dict(scene(gap={"file": "p.csv"}), base=tmp_path)
    message = str(exc.value)
    assert "\n" not in message and f"p.csv:{line}:" in message and words in message, message


@pytest.mark.parametrize("value, key, words", [
    ({"file": "missing.csv"}, "boundary.bottom.gap.file", "cannot read it"),
    ({"columns": ["s", "g"]}, "boundary.bottom.gap.file", "a table from a file is"),
    ({"file": "p.csv", "columns": ["s", "z"]}, "boundary.bottom.gap.columns[1]", "no column of that name"),
    ({"file": "p.csv", "columns": [1, 5]}, "boundary.bottom.gap.columns[1]", "the file has 3 columns"),
    ({"file": "p.csv", "columns": ["s"]}, "boundary.bottom.gap.columns", "must list 2 columns"),
    ({"file": "p.csv"}, "boundary.bottom.gap", "needs 2 columns"),
    ({"file": "p.csv", "sheet": 1}, "boundary.bottom.gap.sheet", "unknown key"),
])
def test_bad_references_are_refused(tmp_path, value, key, words):
    (tmp_path / "p.csv").write_text("s,g,h\n0,0,0\n1,1,1\n")
    with pytest.raises(ConfigError) as exc:
        from_dict(scene(**{"gap": value}), base=tmp_path)
    assert exc.value.key == key and words in str(exc.value), str(exc.value)


def test_every_table_key_reads_a_file(tmp_path):
    """Traction, a displacement component, the body force and the memory kernel read files as inline rows."""
    (tmp_path / "load.csv").write_text("t,fx,fy\n0,0,-1\n1,0,-2\n")
    (tmp_path / "u.csv").write_text("t,u\n0,0\n1,-0.01\n")
    (tmp_path / "kernel.csv").write_text("s,g\n0,1\n1,0.5\n2,0.25\n")
    doc = {"boundary": {"left": LEFT, "right": {"role": "traction", "traction": {"file": "load.csv"}},
                        "top": {"role": "displacement", "displacement": ["free", {"file": "u.csv"}]}},
           "body_force": {"f": {"file": "load.csv", "columns": ["t", "fy", "fx"]}},
           "memory": {"kernel": "tabulated", "table": {"file": "kernel.csv"}}}
    cfg = from_dict(doc, base=tmp_path)
    inline = from_dict({"boundary": {"left": LEFT, "right": {"role": "traction", "traction": [[0, 0, -1], [1, 0, -2]]},
                                     "top": {"role": "displacement", "displacement": ["free", [[0, 0], [1, -0.01]]]}},
                        "body_force": {"f": [[0, -1, 0], [1, -2, 0]]},
                        "memory": {"kernel": "tabulated", "table": [[0, 1], [1, 0.5], [2, 0.25]]}})
    assert cfg.boundaries == inline.boundaries and cfg.body_force == inline.body_force and cfg.memory == inline.memory
    assert cfg.tractions[0].traction_at(0.5) == (0.0, -1.5)


def test_the_resolved_scene_refers_to_copies_and_runs_the_same(tmp_path):
    """dumps_referring writes {file = "tables/<key>.csv"} and lists the copies; written beside it, the scene loads to
    the same Config; a file changed since it was read is written from the rows the run used."""
    (tmp_path / "profile.csv").write_text("x,g,extra\n0,0,1\n0.5,0.01,1\n1,0.04,1\n")
    cfg = from_dict(scene(gap={"file": "profile.csv", "columns": ["x", "g"]}, gap_coordinate="x"), base=tmp_path)
    text, copies = dumps_referring(cfg)
    assert list(copies) == ["tables/boundary.bottom.gap.csv"]
    assert 'gap = {file = "tables/boundary.bottom.gap.csv", columns = ["x", "g"]}' in text
    out = tmp_path / "out"
    (out / "tables").mkdir(parents=True)
    for name, (rows, as_file) in copies.items():
        write_copy(rows, out / name, as_file)
    (out / "config.toml").write_text(text)
    assert load(out / "config.toml").contact == cfg.contact
    (tmp_path / "profile.csv").write_text("x,g,extra\n0,5,1\n1,5,1\n")  # changed after the run read it
    text, copies = dumps_referring(cfg)
    assert 'gap = {file = "tables/boundary.bottom.gap.csv"}' in text
    for name, (rows, as_file) in copies.items():
        write_copy(rows, out / name, as_file)
    assert load(out / "config.toml").contact == cfg.contact
    assert tomllib.loads(dumps(cfg))["boundary"]["bottom"]["gap"] == [[0.0, 0.0], [0.5, 0.01], [1.0, 0.04]]


def test_big_tables_are_written_and_read_in_linear_time():
    """A 10⁵-row inline table: dumps writes it (tomlkit alone takes minutes: O(n²)) and the fast reader gives
    tomllib's document (its integers as floats), falling back to tomllib on anything it is not sure of."""
    s = np.linspace(0.0, 1.0, 100_001)
    cfg = from_dict(scene(gap=[[a, a * a] for a in s.tolist()], gap_coordinate="x"))
    text = dumps(cfg)
    assert fast_loads(text) == tomllib.loads(text)
    assert from_dict(fast_loads(text)).contact == cfg.contact
    rows = ", ".join(f"[{i}, {i}.5e-3]" for i in range(2 * BIG))
    for array in (f"[{rows}]", f"[{rows},]", f"[\n{rows}\n]"):
        assert fast_loads(f"a = {array}\n") == tomllib.loads(f"a = {array}\n")
    for bad in ("[00, 1]", "[.5, 1]", "[1., 1]", "[1e, 1]", "[1 2]", "[1,, 2]", "[+-1, 2]"):
        with pytest.raises(tomllib.TOMLDecodeError):
            fast_loads(f"a = [{rows}, {bad}]\n")
    odd = f'a = """\nb = [{rows}]\n"""\n'  # the array inside a string stays a string
    assert fast_loads(odd) == tomllib.loads(odd)


def test_a_big_inline_table_is_written_back_as_the_scene_gave_it():
    rows = ",\n ".join(f"[{i}, {i}.25e-3]" for i in range(2 * BIG))
    doc = fast_loads(f'[boundary.left]\nrole = "clamped"\n[boundary.bottom]\nrole = "contact"\n'
                     f'gap_coordinate = "x"\ngap = [{rows}]\n')
    cfg = from_dict(doc)
    text, copies = dumps_referring(cfg)
    assert f"gap = [{rows}]" in text and not copies
    assert from_dict(tomllib.loads(text)).contact == cfg.contact
