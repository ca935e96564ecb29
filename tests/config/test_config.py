"""Scenes: defaults are the paper's, overrides, round trip, traction tables, and rejections."""


import pytest
from conftest import ROOT

from solver.config import SECTIONS, Config, ConfigError, apply_overrides, dumps, from_dict, load, to_dict

pytestmark = pytest.mark.serial  # no MPI in this layer: on 2 ranks each would run the same checks again


def test_defaults_are_example1():
    cfg = from_dict({})
    ex1 = load(ROOT / "configs/example1.toml")
    for section in ("material", "memory", "damage", "time"):
        assert getattr(cfg, section) == getattr(ex1, section)
    assert cfg.boundaries == ex1.boundaries
    assert cfg.material.E == 100.0 and cfg.damage.q_star == 1.0 and cfg.contact[0].mu == 1e-10


def test_overrides_documented_keys():
    cfg = load(ROOT / "configs/example1.toml",
               ["mesh.nx=64", "mesh.ny=64", "time.k=0.002", "output.every=0", "boundary.right.traction=[-5, -5]"])
    assert (cfg.mesh.nx, cfg.mesh.ny, cfg.time.k, cfg.time.steps, cfg.output.every) == (64, 64, 0.002, 500, 0)
    assert cfg.tractions[0].traction_at(0.3) == (-5.0, -5.0)


def test_round_trip(tmp_path):
    cfg = load(ROOT / "configs/example1.toml", ["memory.kernel='exponential'", "memory.weights=[-1.0, 2.0]",
                                                "memory.times=[1.0, 0.5]", "solver.petsc_options.mech_snes_max_it=7"])
    path = tmp_path / "c.toml"
    path.write_text(dumps(cfg))
    again = load(path)
    assert again == Config(**{**cfg.__dict__, "source": str(path)})


def test_traction_table_is_left_continuous_at_jumps():
    cfg = from_dict({"boundary": {"left": {"role": "clamped"}, "top": {
        "role": "traction", "traction": [[0.0, 0.0, -10.0], [0.5, 0.0, -10.0], [0.5, 0.0, 0.0], [1.0, 2.0, 0.0]]}}})
    f = cfg.tractions[0].traction_at
    assert f(0.0) == (0.0, -10.0) and f(0.5) == (0.0, -10.0)
    assert f(0.50001) == pytest.approx((0.00004, 0.0)) and f(0.75) == pytest.approx((1.0, 0.0))
    assert f(2.0) == (2.0, 0.0)


_BOX_PARTS = {"left": {"role": "clamped"}, "bottom": {"role": "contact"}}

_BOX_PARTS = {"left": {"role": "clamped"}, "bottom": {"role": "contact"}}

REJECT = [
    ({"meshh": {}}, "meshh"),
    ({"mesh": {"nx": 0}}, "mesh.nx"),
    ({"mesh": {"nx": 8.5}}, "mesh.nx"),
    ({"mesh": {"nx": True}}, "mesh.nx"),
    ({"solver": {"newton_fallback": "yes"}}, "solver.newton_fallback"),
    ({"mesh": {"nx": 100000, "ny": 100000}}, "mesh.nx*mesh.ny"),
    ({"mesh": {"diagonal": "up"}}, "mesh.diagonal"),
    ({"mesh": {"kind": "gmsh", "file": "nope.msh"}}, "mesh.file"),
    ({"mesh": {"corners": [[1, 0], [0, 1]]}}, "mesh.corners"),
    ({"mesh": {"colour": "red"}}, "mesh.colour"),
    ({"material": {"E": 0.0}}, "material.E"),
    ({"material": {"E": float("nan")}}, "material.E"),
    ({"material": {"E": float("inf")}}, "material.E"),
    ({"material": {"E": "stiff"}}, "material.E"),
    ({"material": {"nu": 0.5, "model": "plane_strain"}}, "material.nu"),
    ({"material": {"nu": 1.0}}, "material.nu"),
    ({"material": {"model": "3d"}}, "material.model"),
    ({"boundary": {"bottom": {"role": "contact", "mu": 0.0}, "left": {"role": "clamped"}}}, "boundary.bottom.mu"),
    ({"boundary": {"bottom": {"role": "contact"}}}, "clamped"),
    ({"boundary": {"left": {"role": "glued"}}}, "boundary.left.role"),
    ({"boundary": {"left": {"role": "clamped"}, "edge": {"role": "contact"}}}, "boundary.edge.side"),
    ({"boundary": {"left": {"role": "clamped"}, "right": {"role": "traction"}}}, "boundary.right.traction"),
    ({"boundary": {"left": {"role": "clamped", "traction": [1, 2]}}}, "boundary.left.traction"),
    ({"boundary": {"left": {"role": "clamped"}, "l2": {"role": "contact", "side": "left"}}}, "overlaps"),
    ({"boundary": {"left": {"role": "clamped"}, "right": {"role": "traction", "traction": [[1, 0, 0], [0, 0, 0]]}}},
     "boundary.right.traction"),
    ({"boundary": {"left": {"role": "clamped", "interval": [0.5, 2.0]}}}, "boundary.left.interval"),
    ({"memory": {"kernel": "gamma"}}, "memory.kernel"),
    ({"memory": {"L": -1.0}}, "memory.L"),
    ({"memory": {"kernel": "exponential", "weights": [1.0]}}, "memory.times"),
    ({"memory": {"kernel": "exponential", "weights": [1.0], "times": [0.0]}}, "memory.times[0]"),
    ({"memory": {"kernel": "constant", "times": [1.0]}}, "memory.times"),
    ({"damage": {"kappa": -1.0}}, "damage.kappa"),
    ({"damage": {"zeta_star": 1.5}}, "damage.zeta_star"),
    ({"damage": {"zeta0": 0.001}}, "damage.zeta0"),
    ({"damage": {"q_star": 0.0}}, "damage.q_star"),
    ({"damage": {"enabled": "yes"}}, "damage.enabled"),
    ({"time": {"T": -1.0}}, "time.T"),
    ({"time": {"k": 0.0}}, "time.k"),
    ({"time": {"T": 1.0, "k": 2.0}}, "time.k"),
    ({"time": {"T": 1.0, "k": 0.3}}, "time.k"),
    ({"solver": {"rtol": 2.0}}, "solver.rtol"),
    ({"solver": {"petsc_options": {"mech_x": [1]}}}, "solver.petsc_options.mech_x"),
    ({"output": {"every": -1}}, "output.every"),
    # prescribed displacements and the rigid motions
    ({"boundary": {"left": {"role": "displacement"}}}, "boundary.left.displacement"),
    ({"boundary": {"left": {"role": "displacement", "displacement": [0.0]}}}, "boundary.left.displacement"),
    ({"boundary": {"left": {"role": "displacement", "displacement": [0.0, "fixed"]}}}, "boundary.left.displacement[1]"),
    ({"boundary": {"left": {"role": "displacement", "displacement": ["free", "free"]}}}, "boundary.left.displacement"),
    ({"boundary": {"left": {"role": "displacement", "displacement": [0.0, [[1, 0], [0, 1]]]}}},
     "boundary.left.displacement[1]"),
    ({"boundary": {"left": {"role": "displacement", "displacement": [0.0, [0.1]]}}}, "boundary.left.displacement[1]"),
    ({"boundary": {"left": {"role": "clamped", "displacement": [0.0, 0.0]}}}, "boundary.left.displacement"),
    ({"boundary": {"left": {"role": "displacement", "displacement": [0.0, "free"]}, "bottom": {"role": "contact"}}},
     "no part fixes u_y"),
    # compliance laws and gaps
    ({"boundary": {"left": {"role": "clamped"}, "bottom": {"role": "contact", "law": "hertz"}}}, "boundary.bottom.law"),
    ({"boundary": {"left": {"role": "clamped"}, "bottom": {"role": "contact", "law": "power", "exponent": 2.0}}},
     "boundary.bottom.coefficient"),
    ({"boundary": {"left": {"role": "clamped"}, "bottom": {"role": "contact", "law": "power", "coefficient": 1.0,
                                                            "exponent": 0.5}}}, "boundary.bottom.exponent"),
    ({"boundary": {"left": {"role": "clamped"}, "bottom": {"role": "contact", "law": "power", "coefficient": 1.0,
                                                            "exponent": 2.0, "mu": 1e-10}}}, "boundary.bottom.mu"),
    ({"boundary": {"left": {"role": "clamped"}, "bottom": {"role": "contact", "coefficient": 1.0}}},
     "boundary.bottom.coefficient"),
    ({"boundary": {"left": {"role": "clamped"}, "bottom": {"role": "contact", "law": "limited_penetration", "mu": 1e-2}}},
     "boundary.bottom.depth"),
    ({"boundary": {"left": {"role": "clamped"}, "bottom": {"role": "contact", "law": "limited_penetration", "mu": 1e-2,
                                                            "depth": 0.1, "mu_stiff": 1.0}}}, "boundary.bottom.mu_stiff"),
    ({"boundary": {"left": {"role": "clamped"}, "bottom": {"role": "contact", "gap": [[0.0, 0.1], [0.0, 0.2]]}}},
     "boundary.bottom.gap"),
    ({"boundary": {"left": {"role": "clamped"}, "bottom": {"role": "contact", "gap": [0.0, 0.1]}}}, "boundary.bottom.gap"),
    ({"boundary": {"left": {"role": "clamped"}, "bottom": {"role": "contact", "gap_coordinate": "x"}}},
     "boundary.bottom.gap_coordinate"),
    ({"boundary": {"left": {"role": "clamped"}, "bottom": {"role": "contact", "gap": [[0, 0], [1, 0]], "gap_coordinate": "z"}}},
     "boundary.bottom.gap_coordinate"),
    ({"boundary": {"left": {"role": "clamped"}, "bottom": {"role": "contact", "law": "power", "coefficient": 1.0,
                                                            "exponent": 2.0}},
      "solver": {"method": "penalty_duality"}}, "solver.method"),
    # body force
    ({"body_force": {"f": [0.0, -9.81, 0.0]}}, "body_force.f"),
    ({"body_force": {"g": [0.0, -9.81]}}, "body_force.g"),
    ({"body_force": {"f": [[0.0, 0.0, 0.0], [-1.0, 0.0, 1.0]]}}, "body_force.f"),
    ({"solver": {"linear": "iterative", "method": "fixed_point"}}, "solver.linear"),
    ({"solver": {"linear": "gmres"}}, "solver.linear"),
    ({"solver": {"contact_points": "vertex"}}, "solver.contact_points"),
    ({"solver": {"contact_points": 1}}, "solver.contact_points"),
    ({"mesh": {"kind": "box"}, "boundary": _BOX_PARTS, "material": {"model": "3d"}, "discretization": {"u_degree": 2},
      "solver": {"contact_points": "nodes"}}, "solver.contact_points"),
    # the built-in box
    *[({"mesh": {"kind": "box", **m}, "boundary": _BOX_PARTS, "material": {"model": "3d"}}, key) for m, key in (
        ({"corners": [[0, 0], [1, 1]]}, "mesh.corners[0]"),
        ({"corners": [[0, 0, 0], [1, 1, 0]]}, "mesh.corners"),
        ({"corners": [[0, 0, 0]]}, "mesh.corners"),
        ({"nz": 0}, "mesh.nz"),
        ({"diagonal": "left"}, "mesh.diagonal"),
        ({"nx": 1000, "ny": 1000, "nz": 1000}, "mesh.nx*mesh.ny*mesh.nz"),
    )],
    ({"mesh": {"nz": 4}}, "mesh.nz"),
    ({"mesh": {"kind": "box"}, "boundary": _BOX_PARTS}, "material.model"),
    ({"mesh": {"kind": "box"}, "boundary": _BOX_PARTS, "material": {"model": "plane_strain"}}, "material.model"),
    ({"mesh": {"kind": "box"}, "material": {"model": "3d"}}, "boundary"),
    ({"material": {"model": "3d"}}, "material.model"),
    ({"mesh": {"kind": "box"}, "material": {"model": "3d"},
      "boundary": {**_BOX_PARTS, "side": {"role": "traction", "traction": [1.0, 0.0, 0.0], "side": "middle"}}},
     "boundary.side.side"),
    ({"mesh": {"kind": "box"}, "material": {"model": "3d"},
      "boundary": {**_BOX_PARTS, "front": {"role": "traction", "traction": [1.0, 0.0, 0.0], "interval": [0.0, 0.5]}}},
     "boundary.front.interval"),
    ({"mesh": {"kind": "box"}, "material": {"model": "3d"},
      "boundary": {**_BOX_PARTS, "front": {"role": "traction", "traction": [1.0, 0.0, 0.0],
                                            "interval": [[0.0, 0.5], [0.5, 1.5]]}}},
     "boundary.front.interval[1]"),
    ({"mesh": {"kind": "box"}, "material": {"model": "3d"},
      "boundary": {**_BOX_PARTS, "b2": {"role": "traction", "traction": [1.0, 0.0, 0.0], "side": "bottom",
                                         "interval": [[0.5, 1.0], [0.5, 1.0]]}}},
     "boundary.b2"),
    ({"mesh": {"kind": "box"}, "material": {"model": "3d"},
      "boundary": {"left": {"role": "clamped"}, "bottom": {"role": "contact", "gap": [[0, 0], [1, 0.1]]}}},
     "boundary.bottom.gap_coordinate"),
]


@pytest.mark.parametrize("data,key", REJECT, ids=[k for _, k in REJECT])
def test_rejections_name_the_key(data, key):
    with pytest.raises(ConfigError) as err:
        from_dict(data, source="scene.toml")
    msg = str(err.value)
    assert msg.startswith("scene.toml: ") and key in msg and "\n" not in msg


def test_bad_files(tmp_path):
    empty = tmp_path / "empty.toml"
    empty.write_text("")
    with pytest.raises(ConfigError, match="empty"):
        load(empty)
    bad = tmp_path / "bad.toml"
    bad.write_text("[mesh\nnx = 3")
    with pytest.raises(ConfigError, match="not valid TOML"):
        load(bad)
    fake = tmp_path / "fake.msh"
    fake.write_text("hello")
    scene = tmp_path / "s.toml"
    scene.write_text('[mesh]\nkind = "gmsh"\nfile = "fake.msh"\n')
    with pytest.raises(ConfigError, match="not a gmsh"):
        load(scene)
    with pytest.raises(ConfigError, match="no such scene"):
        load(tmp_path / "missing.toml")


def test_override_syntax():
    with pytest.raises(ConfigError, match="section.key"):
        apply_overrides({}, ["nx=3"])
    assert apply_overrides({}, ["mesh.diagonal=left"]) == {"mesh": {"diagonal": "left"}}
    assert apply_overrides({}, ["mesh.nx=3"]) == {"mesh": {"nx": 3}}  # the value syntax is TOML's


def test_contact_points_round_trip_and_leave_the_default_scene_as_it_was(tmp_path):
    """"nodes" survives dumps -> load; the default "gauss" is not written, so a default scene's resolved text (and its
    checkpoint hash) is the one before the key."""
    default = from_dict({})
    assert default.solver.contact_points == "gauss" and "contact_points" not in dumps(default)
    nodes = from_dict({"solver": {"contact_points": "nodes"}})
    path = tmp_path / "c.toml"
    path.write_text(dumps(nodes))
    assert 'contact_points = "nodes"' in path.read_text() and load(path).solver.contact_points == "nodes"


def test_new_keys_round_trip_and_defaults(tmp_path):
    """Body force, displacement parts, laws and gap tables survive dumps -> load; gap coordinates default by side."""
    cfg = from_dict({
        "boundary": {
            "left": {"role": "displacement", "displacement": [0.0, "free"]},
            "bottom": {"role": "displacement", "displacement": ["free", [[0.0, 0.0], [1.0, -0.1]]]},
            "top": {"role": "contact", "gap": [[0.0, 0.1], [1.0, 0.2]], "law": "power", "coefficient": 1e3, "exponent": 1.5},
            "right": {"role": "contact", "gap": [[0.0, 0.0], [1.0, 0.1]], "law": "limited_penetration", "mu": 1e-2,
                      "depth": 0.01},
        },
        "body_force": {"f": [[0.0, 0.0, 0.0], [1.0, 0.0, -9.81]]},
    })
    path = tmp_path / "c.toml"
    path.write_text(dumps(cfg))
    again = load(path)
    assert again == Config(**{**cfg.__dict__, "source": str(path)})
    parts = {b.name: b for b in cfg.boundaries}
    assert parts["top"].gap_coordinate == "x" and parts["right"].gap_coordinate == "y"
    assert parts["right"].mu_stiff == 1e-10
    assert parts["left"].fixed(2) == (True, False) and parts["bottom"].displacement_at(0.5, 2) == (None, -0.05)
    assert cfg.body_force.at(0.25) == pytest.approx((0.0, -9.81 / 4))
    assert from_dict({}).body_force.f == ()  # no [body_force]: no body force term at all


def test_a_scene_without_a_clamped_part_is_valid_when_every_direction_is_fixed():
    cfg = from_dict({"boundary": {"left": {"role": "displacement", "displacement": [0.0, "free"]},
                                  "bottom": {"role": "displacement", "displacement": ["free", 0.0]},
                                  "top": {"role": "traction", "traction": [0.0, -1.0]}}})
    assert [b.role for b in cfg.dirichlet] == ["displacement", "displacement"] and not cfg.clamped


def test_gap_table_on_a_gmsh_part_needs_its_coordinate():
    data = {"mesh": {"kind": "gmsh", "file": "meshes/example2.msh"},
            "boundary": {"clamped": {"role": "clamped"}, "contact": {"role": "contact", "gap": [[0.0, 0.0], [1.0, 0.1]]}}}
    with pytest.raises(ConfigError) as err:
        from_dict(data, source="scene.toml", base=ROOT)
    assert err.value.key == "boundary.contact.gap_coordinate"
    data["boundary"]["contact"]["gap_coordinate"] = "y"
    assert from_dict(data, base=ROOT).contact[0].gap_table == ((0.0, 0.0), (1.0, 0.1))


    # values are TOML; a bare word is a string
    assert apply_overrides({}, ["time.k=1e-3", "mesh.corners=[[0, 0], [2, 1]]", "solver.linear=mumps"]) == {
        "time": {"k": 1e-3}, "mesh": {"corners": [[0, 0], [2, 1]]}, "solver": {"linear": "mumps"}}


def test_errors_carry_the_key_value_and_what_is_allowed():
    with pytest.raises(ConfigError) as err:
        from_dict({"mesh": {"nx": 0}}, source="s.toml")
    assert (err.value.source, err.value.key, err.value.value) == ("s.toml", "mesh.nx", 0)
    assert err.value.allowed == "must be at least 1"
    with pytest.raises(ConfigError) as err:
        from_dict({"meshes": {}})
    assert err.value.key == "meshes" and all(s.key in err.value.allowed for s in SECTIONS)


def test_sections_registry_drives_parsing_and_writing():
    cfg = from_dict({})
    assert list(to_dict(cfg)) == [s.key for s in SECTIONS]
    assert all(hasattr(cfg, s.attr) for s in SECTIONS)
    with pytest.raises(ConfigError) as err:
        from_dict({"material": {"model": "3d"}})  # the material section sees the mesh's dimension
    assert err.value.key == "material.model"


@pytest.mark.parametrize("data,key", [
    ({"discretization": {"u_degree": 3}}, "discretization.u_degree"),
    ({"discretization": {"zeta_degree": 0}}, "discretization.zeta_degree"),
    ({"time": {"order": 3}}, "time.order"),
    ({"time": {"order": 2}, "memory": {"kernel": "power"}}, "memory.rule"),
    ({"time": {"order": 2}, "memory": {"rule": "left"}}, "memory.rule"),
    ({"time": {"order": 2}, "solver": {"damage_scheme": "semi_implicit"}}, "solver.damage_scheme"),
])
def test_discretization_and_order_are_validated(data, key):
    with pytest.raises(ConfigError) as err:
        from_dict(data)
    assert err.value.key == key


def test_degrees_choose_the_quadrature_and_the_order_chooses_the_memory_rule():
    p1 = from_dict({})
    assert (p1.solver.quadrature_degree, p1.solver.contact_quadrature_degree, p1.memory.rule) == (1, 2, "left")
    p2 = from_dict({"discretization": {"u_degree": 2}, "time": {"order": 2}})
    assert (p2.solver.quadrature_degree, p2.solver.contact_quadrature_degree) == (3, 4)
    assert p2.memory.rule == "trapezoid_extrapolated"
    mine = from_dict({"discretization": {"u_degree": 2}, "solver": {"quadrature_degree": 5}})
    assert mine.solver.quadrature_degree == 5  # an explicit setting wins


def test_box_round_trips_and_is_three_dimensional():
    cfg = load(ROOT / "configs/example1_3d.toml", ["boundary.top.role='traction'", "boundary.top.traction=[0, 0, 1]",
                                                     "boundary.top.interval=[[0.25, 0.75], [0.0, 0.5]]"])
    assert cfg.dim == 3 and cfg.mesh.kind == "box" and cfg.mesh.nz == 8
    top = next(b for b in cfg.boundaries if b.name == "top")
    assert top.patch == ((0.25, 0.75), (0.0, 0.5)) and top.interval is None
    again = from_dict(to_dict(cfg), source=cfg.source)
    assert again == cfg
    assert "diagonal" not in to_dict(cfg)["mesh"] and "nz" not in to_dict(load(ROOT / "configs/example1.toml"))["mesh"]


def test_a_gmsh_files_dimension_is_read_once_per_version_of_the_file(tmp_path):
    import os
    import shutil

    from solver.config.mesh import _gmsh_dim, gmsh_dim

    msh = tmp_path / "m.msh"
    shutil.copy(ROOT / "meshes" / "example2.msh", msh)
    assert gmsh_dim(str(msh)) == 2
    hits = _gmsh_dim.cache_info().hits
    assert gmsh_dim(str(msh)) == 2 and _gmsh_dim.cache_info().hits == hits + 1
    os.utime(msh, ns=(0, 1))  # a new version of the file (another mtime): read again
    misses = _gmsh_dim.cache_info().misses
    assert gmsh_dim(str(msh)) == 2 and _gmsh_dim.cache_info().misses == misses + 1


EX1 = ROOT / "configs/example1.toml"


@pytest.mark.parametrize("changes, sets", [
    ({"time": {"k": 0.005}, "mesh": {"nx": 32}}, ["time.k=0.005", "mesh.nx=32"]),
    ({"time": {"order": 2}}, ["time.order=2"]),  # memory.rule 'auto' re-derived, as in the file
    ({"discretization": {"u_degree": 2}}, ["discretization.u_degree=2"]),  # quadrature degrees re-derived
    ({"boundary": {"bottom": {"mu": 1e-3}}, "output": {"xdmf": False}}, ["boundary.bottom.mu=1e-3", "output.xdmf=false"]),
])
def test_replace_equals_the_file_with_the_same_sets(changes, sets):
    cfg = load(EX1)
    new = cfg.replace(changes)
    assert new == load(EX1, sets) and new.source == str(EX1)
    assert cfg == load(EX1)  # the original is unchanged
    assert new.replace({"time": {"T": 2.0}}) == load(EX1, [*sets, "time.T=2.0"])  # replacements chain


def test_replace_on_a_gmsh_scene_keeps_its_mesh_file():
    path = ROOT / "configs/example2.toml"
    assert load(path).replace({"time": {"k": 0.05}}) == load(path, ["time.k=0.05"])


@pytest.mark.parametrize("changes, key, value", [
    ({"time": {"k": 0.3}}, "time.k", 0.3),
    ({"mesh": {"nx": 0}}, "mesh.nx", 0),
    ({"time": {"kk": 1}}, "time.kk", 1),
    ({"time": {"k": {"a": 1}}}, "time.k", 0.01),  # a table where a value is
])
def test_replace_rejects_like_a_file(changes, key, value):
    with pytest.raises(ConfigError) as err:
        load(EX1).replace(changes, label="my study")
    e = err.value
    assert (e.key, e.value, e.source) == (key, value, f"{EX1} (my study)")
    assert str(e).count("\n") == 0 and str(e).startswith(f"{EX1} (my study): {key} = ")


def test_replace_applies_the_checks_across_sections():
    cfg = load(EX1)
    with pytest.raises(ConfigError) as err:  # [solver] reads [time]
        cfg.replace({"time": {"order": 2}, "solver": {"damage_scheme": "semi_implicit"}})
    assert err.value.key == "solver.damage_scheme" and err.value.source == f"{EX1} (replace())"
    with pytest.raises(ConfigError) as err:  # [memory] reads [time]
        cfg.replace({"time": {"order": 2}, "memory": {"rule": "left"}})
    assert err.value.key == "memory.rule"
    with pytest.raises(ConfigError) as err:  # [memory] reads time.adaptive
        cfg.replace({"time": {"adaptive": True}, "memory": {"kernel": "power"}})
    assert err.value.key == "memory.kernel"


def test_replace_without_a_document_uses_the_resolved_scene():
    cfg = Config(**{**from_dict({}).__dict__, "document": None})
    assert cfg.replace({"mesh": {"nx": 8}}).mesh.nx == 8


def test_replace_merges_a_part_and_a_whole_part_changes_its_role():
    """What docs/python.md says: a change merges key by key (role and gap kept), so a new role is refused; the
    part written whole into a new scene takes it."""
    cfg = load(EX1)
    merged = cfg.replace({"boundary": {"bottom": {"mu": 1e-3}}})
    assert merged.document["boundary"]["bottom"] == {**cfg.document["boundary"]["bottom"], "mu": 1e-3}
    with pytest.raises(ConfigError) as err:
        cfg.replace({"boundary": {"bottom": {"role": "traction", "traction": [0.0, 0.0]}}})
    assert err.value.key == "boundary.bottom.gap" and "not used by role 'traction'" in str(err.value)
    parts = {**cfg.document["boundary"], "bottom": {"role": "traction", "traction": [0.0, 0.0]}}
    free = from_dict({**cfg.document, "boundary": parts}, source=cfg.source)
    assert not free.contact and free == load(EX1, ['boundary.bottom={role="traction", traction=[0.0, 0.0]}'])


def test_adaptive_time_keys():
    """time.adaptive: k need not divide T; the bounds and output.times are checked; the adaptive keys (and
    output.times) are refused without it, and a tabulated kernel is refused with it (one line each)."""
    ex1 = ROOT / "configs/example1.toml"
    cfg = load(ex1, ["time.adaptive=true", "time.k=0.003", "time.tolerance=1e-4", "time.k_max=0.1",
                     "output.times=[0.25, 0.5]"])
    assert cfg.time.adaptive and cfg.time.smallest == pytest.approx(1e-9) and cfg.time.largest == 0.1
    assert cfg.output.times == (0.25, 0.5)
    assert "adaptive =" not in dumps(load(ex1))  # a uniform scene's resolved file is as it was
    assert load(ex1, ["time.adaptive=true"]).replace({}).time.adaptive
    for sets, key in ((["time.tolerance=1e-3"], "time.tolerance"), (["time.k=0.003"], "time.k"),
                      (["time.adaptive=true", "time.k_max=0.001"], "time.k_max"),
                      (["time.adaptive=true", "time.k_min=0.1"], "time.k_min"),
                      (["output.times=[0.5]"], "output.times"),
                      (["time.adaptive=true", "output.times=[2.0]"], "output.times"),
                      (["time.adaptive=true", "memory.kernel='tabulated'", "memory.table=[[0.0, 1.0], [1.0, 0.5]]"],
                       "memory.kernel")):
        with pytest.raises(ConfigError) as err:
            load(ex1, sets)
        assert key in str(err.value) and "\n" not in str(err.value), (sets, str(err.value))
