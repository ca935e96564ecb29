"""Checkpoints: the scene hash, the coordinate keys, and a write/read round trip that restores the state."""

from dataclasses import replace

import numpy as np
import pytest
from conftest import ROOT, checkpointed
from petsc4py import PETSc

from solver.config import OutputConfig, from_dict
from solver.errors import ConfigError
from solver.io import checkpoint
from solver.run.model import build_model
from solver.run.stepper import Stepper

SCENE = {"mesh": {"nx": 4, "ny": 4}, "time": {"T": 0.3, "k": 0.1}}


def test_scene_hash_ignores_output_settings_only():
    cfg = from_dict(SCENE)
    assert checkpoint.scene_hash(cfg) == checkpoint.scene_hash(replace(cfg, output=OutputConfig(every=7)))
    assert checkpoint.scene_hash(cfg) != checkpoint.scene_hash(from_dict({**SCENE, "material": {"E": 101.0}}))
    other = from_dict({**SCENE, "material": {"E": 101.0}})
    first = checkpoint.scene_hash(other)
    assert checkpoint.scene_hash(other) == first != checkpoint.scene_hash(cfg)  # the kept hash is the same scene's
    # the contact's rule defines the solution: a checkpoint of one rule does not restart the other
    assert checkpoint.scene_hash(from_dict({**SCENE, "solver": {"contact_points": "nodes"}})) != checkpoint.scene_hash(cfg)


def test_keys_sort_points_by_coordinates():
    pts = np.array([[0.5, 0.0], [0.0, 1.0], [0.0, 0.5]])
    assert list(np.argsort(checkpoint._keys(pts))) == [2, 1, 0]


@pytest.mark.parametrize("dim", [2, 3])
def test_the_written_order_is_the_keys_order(dim):
    """checkpoint._order (lexsort on the columns, issue 30) puts distinct points in the order np.argsort(_keys) did,
    so a run writes the same file: grid points (ties in x, in y) in a shuffled order, some at -0.0."""
    rng = np.random.default_rng(1)
    pts = np.unique(rng.integers(-2, 4, size=(400, dim)) / 5.0, axis=0)
    pts[pts == 0.0] = -0.0
    pts = np.vstack([pts, np.full((1, dim), 0.1 + 3e-11)])  # rounds (1e-10) onto no other point
    pts = pts[rng.permutation(len(pts))]
    assert np.array_equal(checkpoint._order(pts), np.argsort(checkpoint._keys(pts)))


def test_round_trip_restores_every_field(comm, shared_tmp):
    model, _, fresh = checkpointed(from_dict(SCENE), comm, shared_tmp, 2)
    saved = {"u": model.u.x.array.copy(), "zeta": model.damage.zeta.x.array.copy(), "M": model.history.M.x.array.copy()}
    ck = checkpoint.read(shared_tmp, fresh)
    assert (ck.step, ck.t, ck.part) == (1, pytest.approx(0.1), 1)
    assert np.array_equal(fresh.u.x.array, saved["u"])  # same partition here: same order
    assert np.array_equal(fresh.damage.zeta.x.array, saved["zeta"])
    # owned quadrature values exactly; ghost-cell values are computed locally during a run (round-off from the
    # owner's, in another summation order) and read from their owner after a restart
    Q = model.history.M.function_space
    owned = Q.dofmap.index_map.size_local * Q.dofmap.index_map_bs
    assert np.array_equal(fresh.history.M.x.array[:owned], saved["M"][:owned])
    assert np.allclose(fresh.history.M.x.array, saved["M"], rtol=0, atol=1e-14 * np.abs(saved["M"]).max())
    assert fresh.mech.problem.carried


def test_read_refuses_another_scene(comm, shared_tmp):
    model = build_model(from_dict(SCENE), comm)
    Stepper(model).step(0)
    checkpoint.write(shared_tmp, model, 0, 0.0, part=0)
    other = build_model(from_dict({**SCENE, "material": {"E": 50.0}}), comm)
    with pytest.raises(ConfigError, match="scene differs"):
        checkpoint.read(shared_tmp, other)


def test_round_trip_carries_the_cnab2_damage_state(comm, shared_tmp):
    """The second-order damage's previous source and its 'have one' flag come back, and the next step is the
    same as the uninterrupted one's, to the bit."""
    cfg = from_dict({**SCENE, "time": {**SCENE["time"], "order": 2}})
    model, stepper, fresh = checkpointed(cfg, comm, shared_tmp, 3)
    assert not fresh.damage.have_prev
    checkpoint.read(shared_tmp, fresh)
    assert fresh.damage.scalars() == model.damage.scalars() == {"have_prev": 1.0}
    assert np.array_equal(fresh.damage.state()["source_prev"], model.damage.state()["source_prev"])
    assert fresh.damage.state()["source_prev"].any()
    stepper.step(3)
    Stepper(fresh).step(3)
    assert np.array_equal(fresh.damage.zeta.x.array, model.damage.zeta.x.array)


def test_round_trip_carries_the_condensed_predictor(comm, shared_tmp):
    """newton_condensed predicts a level's first active set from the last two levels' contact dofs: a restart
    carries the older one, so the levels after it take the same iterations and reach the same u (to the bit on
    one rank; hard.toml with P2: level 34's zone moves, 10 iterations)."""
    import tomllib

    with open(ROOT / "configs" / "hard.toml", "rb") as fh:
        scene = tomllib.load(fh)
    scene["discretization"] = {"u_degree": 2, "zeta_degree": 2}
    scene["time"]["order"] = 2
    scene["solver"] = {"method": "newton_condensed"}
    model, stepper, fresh = checkpointed(from_dict(scene), comm, shared_tmp, 34)
    checkpoint.read(shared_tmp, fresh)
    # the same values (in the order of each build's partition)
    assert np.array_equal(np.sort(fresh.mech.solver.previous), np.sort(model.mech.solver.previous))
    again = Stepper(fresh)
    for n in range(34, 37):
        a, b = stepper.step(n), again.step(n)
        assert a["newton_iterations"] == b["newton_iterations"], n
        if comm.size == 1:  # the same arithmetic
            assert np.array_equal(fresh.u.x.array, model.u.x.array), n
        else:  # two builds may partition differently, and ghost values come back from their owners: the norms
            for kind in (PETSc.NormType.NORM_2, PETSc.NormType.NORM_INFINITY):
                assert fresh.u.vector.norm(kind) == pytest.approx(model.u.vector.norm(kind), rel=1e-10), n


def _edited_checkpoint(comm, directory, edit):
    """A level-0 checkpoint of SCENE whose file ``edit(h5)`` changes (on rank 0), and a fresh model to read it."""
    import h5py

    model = build_model(from_dict(SCENE), comm)
    Stepper(model).step(0)
    checkpoint.write(directory, model, 0, 0.0, part=0)
    comm.barrier()
    if comm.rank == 0:
        with h5py.File(directory / checkpoint.NAME, "r+") as h5:
            edit(h5)
    comm.barrier()
    return build_model(from_dict(SCENE), comm)


@pytest.mark.parametrize("drop", ["field", "scalar"])
def test_read_refuses_a_checkpoint_lacking_what_this_version_keeps(comm, shared_tmp, drop):
    """A checkpoint written by a version that kept fewer fields or values (an adaptive run's accumulated errors,
    say) is refused with one line naming what it lacks, not a KeyError from h5py."""

    def edit(h5):
        if drop == "field":
            del h5["zeta"]
        else:
            del h5.attrs[next(k for k in h5.attrs if k.startswith("mech_"))]

    fresh = _edited_checkpoint(comm, shared_tmp, edit)
    with pytest.raises(ConfigError, match="lacks .*another version") as e:
        checkpoint.read(shared_tmp, fresh)
    assert "\n" not in str(e.value)


@pytest.mark.parametrize("version", [None, 2, 0])
def test_read_checks_the_checkpoint_format(comm, shared_tmp, version):
    """The file carries its format: one without it (written before the attribute) reads as format 1; one of another
    format is refused with one line naming both formats."""

    def edit(h5):
        assert h5.attrs["format"] == checkpoint.FORMAT
        if version is None:
            del h5.attrs["format"]
        else:
            h5.attrs["format"] = version

    fresh = _edited_checkpoint(comm, shared_tmp, edit)
    if version is None:
        assert checkpoint.read(shared_tmp, fresh).step == 0
        return
    with pytest.raises(ConfigError, match=f"checkpoint format {version}, this solver reads format 1") as e:
        checkpoint.read(shared_tmp, fresh)
    assert ("a newer" if version > 1 else "an older") in str(e.value) and "\n" not in str(e.value)
