"""contact.xdmf: Γ_C as a facet mesh (segments in 2-D, triangles in 3-D) with the contact results and the displacement
at its vertices, at every written level; the same values as contact.csv and solution.xdmf, on 1 and 2 ranks, and a
restart cuts and continues it as it does the body's series."""

import numpy as np
import pytest
from conftest import solve

from solver.config import from_dict
from solver.io.xdmf import read_series
from solver.post.results import read_profile, read_results

SCENES = {
    "2d": {"mesh": {"nx": 12, "ny": 4}, "time": {"T": 0.3, "k": 0.1}},
    "3d": {"mesh": {"kind": "box", "corners": [[0, 0, 0], [1, 1, 1]], "nx": 3, "ny": 4, "nz": 3},
           "material": {"model": "3d"}, "time": {"T": 0.2, "k": 0.1}, "memory": {"kernel": "none"},
           "boundary": {"left": {"role": "clamped"}, "right": {"role": "traction", "traction": [0.0, 0.0, -20.0]},
                        "bottom": {"role": "contact", "gap": 0.0, "mu": 1e-3}}},
}


def _match(points: np.ndarray, other: np.ndarray) -> np.ndarray:
    """For each of ``points``, the index of the same point in ``other``."""
    index = {tuple(np.round(p, 12)): i for i, p in enumerate(other)}
    return np.array([index[tuple(np.round(p, 12))] for p in points])


@pytest.mark.parametrize("scene", sorted(SCENES))
def test_the_contact_dataset_holds_gamma_c_and_its_results(comm, shared_tmp, scene):
    cfg = from_dict({**SCENES[scene], "output": {"every": 1, "fields": ["displacement", "contact_pressure"]}})
    model, _ = solve(cfg, comm, shared_tmp)
    if comm.rank != 0:
        return
    dim = model.geo.dim
    contact = read_series(shared_tmp / "contact.xdmf")
    body = read_results(shared_tmp)
    profile = read_profile(shared_tmp / "contact.csv")
    points, cells = contact["points"], contact["cells"]
    assert cells.shape[1] == dim  # segments in 2-D, triangles in 3-D
    n = cfg.mesh.nx
    assert len(cells) == (n if dim == 2 else 2 * cfg.mesh.nx * cfg.mesh.ny)  # the bottom's facets
    assert np.all(np.abs(points[:, dim - 1]) < 1e-12)  # Γ_C is the bottom: y = 0 (z = 0 in 3-D)
    assert len(np.unique(cells)) == len(points)  # every node belongs to a facet
    assert contact["times"] == body["times"]
    at_body = _match(points, body["geometry"][:, : points.shape[1]])
    for i, t in enumerate(contact["times"]):
        fields = {name: values[i] for name, values in contact["fields"].items()}
        assert set(fields) == {"contact_pressure", "gap", "penetration", "normal_displacement", "displacement"}
        assert np.array_equal(fields["displacement"][:, :dim], body["fields"]["displacement"][t][at_body][:, :dim])
        assert np.array_equal(fields["contact_pressure"], body["fields"]["contact_pressure"][t][at_body])
        rows = profile[(i, "bottom")]
        at_profile = _match(points, np.column_stack([rows[a] for a in "xyz"[: points.shape[1]]]))
        for name, column in (("contact_pressure", "pressure"), ("gap", "gap"), ("penetration", "penetration"),
                             ("normal_displacement", "u_normal")):
            assert np.array_equal(fields[name], rows[column][at_profile]), name
        assert fields["contact_pressure"].min() >= 0.0
    assert contact["fields"]["contact_pressure"][-1].max() > 0


def test_a_restart_cuts_and_continues_the_contact_dataset(comm, shared_tmp):
    """Run to T = 0.5 with a checkpoint at step 4, then restart from it: the dataset keeps levels 0-4, drops the
    first run's level 5 and appends it again, equal to the first run's."""
    cfg = from_dict({**SCENES["2d"], "time": {"T": 0.5, "k": 0.1}, "output": {"every": 1, "checkpoint_every": 2}})
    solve(cfg, comm, shared_tmp)
    first = read_series(shared_tmp / "contact.xdmf") if comm.rank == 0 else None
    solve(cfg, comm, shared_tmp, restart=True)
    if comm.rank != 0:
        return
    again = read_series(shared_tmp / "contact.xdmf")
    assert again["times"] == first["times"] == pytest.approx([0.0, 0.1, 0.2, 0.3, 0.4, 0.5])
    for name, values in first["fields"].items():
        for a, b in zip(values, again["fields"][name]):
            assert np.allclose(a, b, rtol=1e-12, atol=1e-14 * np.abs(values[-1]).max())
    listed = {p.name for p in (shared_tmp / "fields").glob("contact_levels_*.h5")}
    named = {item.split(":")[0].split("/")[-1] for item in (shared_tmp / "contact.xdmf").read_text().split(">")
             if ".h5:" in item}
    assert listed == named - {"contact_mesh.h5"}  # no chunk file left that the XML does not name
