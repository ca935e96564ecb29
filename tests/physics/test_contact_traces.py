"""The contact traces are the lumped-mass (row-sum) L² projection onto P1 of the law's values at the contact term's
quadrature points: p_i = ∫ p(u_ν − g) φ_i ds / ∫ φ_i ds, nonnegative, with Σ_i m_i p_i the contact force, and a
penetration whose sign is the pressure's."""

import numpy as np
import pytest
import ufl
from dolfinx import fem
from mpi4py import MPI

from solver.config import from_dict
from solver.run.model import build_model

MU = 1e-3
SCENES = {
    "2d": {"mesh": {"nx": 6, "ny": 5}, "boundary": {"top": {"role": "clamped"},
                                                 "bottom": {"role": "contact", "gap": 0.0, "mu": MU}}},
    "3d": {"mesh": {"kind": "box", "corners": [[0, 0, 0], [1, 1, 1]], "nx": 3, "ny": 4, "nz": 3},
           "material": {"model": "3d"},
           "boundary": {"left": {"role": "clamped"}, "right": {"role": "traction", "traction": [0.0, 0.0, -1.0]},
                        "bottom": {"role": "contact", "gap": 0.0, "mu": MU}}},
}


def _model(comm, scene: str, degree: int = 1):
    cfg = {**SCENES[scene], "memory": {"kernel": "none"}, "damage": {"enabled": False},
           "discretization": {"u_degree": degree}}
    return build_model(from_dict(cfg), comm)


def _press(model, depth):
    """u = −depth(x) along the bottom's outward normal (−e_y in 2-D, −e_z in 3-D): penetration depth(x)."""
    d = model.geo.dim
    model.u.interpolate(lambda x: np.vstack([0.0 * x[0]] * (d - 1) + [-depth(x)]))


@pytest.mark.parametrize("scene", sorted(SCENES))
@pytest.mark.parametrize("degree", [1, 2])
def test_the_pressure_is_the_lumped_mean_of_the_law_and_integrates_to_the_force(comm, scene, degree):
    model = _model(comm, scene, degree)
    traces = model.mech.diagnostics.traces
    # a penetration linear in x, positive on x < 1/2 and negative beyond: a contact zone ending inside Γ_C
    _press(model, lambda x: 1e-6 * (0.5 - x[0]))
    traces.update()
    ds = model.geo.ds(model.geo.tags["bottom"], metadata={"quadrature_degree": 2 * degree})
    n = ufl.FacetNormal(model.geo.mesh)
    force = comm.allreduce(fem.assemble_scalar(fem.form(ufl.max_value(ufl.dot(model.u, n), 0.0) / MU * ds)),
                           op=MPI.SUM)
    assert force > 0
    assert traces.lumped_force() == pytest.approx(force, rel=1e-12)
    p, pen = traces.pressure.x.array, traces.penetration.x.array
    assert comm.allreduce(float(p.min()), op=MPI.MIN) >= 0.0
    assert np.all((p[traces.on] > 0) == (pen[traces.on] > 0))  # a positive pressure has a positive penetration
    assert np.allclose(pen[p > 0], MU * p[p > 0], rtol=1e-12, atol=0)  # the linear law: r₊ = μ p
    off = np.setdiff1d(np.arange(len(p)), traces.on)
    assert np.count_nonzero(p[off]) == 0 and np.count_nonzero(pen[off]) == 0
    # the vertices whose facets are all in contact (x <= 1/2 - h) read the exact linear p (the mean of a linear
    # function over a hat symmetric in x is its value); in 2-D the first vertex (x = 0) reads the mean over half a hat
    x = traces.x[traces.on, 0]
    h = 1.0 / SCENES[scene]["mesh"]["nx"]
    exact = 1e-6 * (0.5 - x) / MU
    inner = (x > 1e-12) & (x < 0.5 - h + 1e-12)
    assert np.allclose(p[traces.on][inner], exact[inner], rtol=1e-12)
    first = x < 1e-12
    if scene == "2d":  # (in 3-D the edge vertices' patches differ in shape)
        assert np.allclose(p[traces.on][first], exact[first] - 1e-6 * h / 3 / MU, rtol=1e-12)
    # separated vertices (x >= 1/2 + h): no pressure, the mean separation u_ν − g < 0
    apart = x > 0.5 + h - 1e-12
    assert np.all(p[traces.on][apart] == 0) and np.all(pen[traces.on][apart] < 0)


def test_the_gap_is_the_mean_of_the_exact_gap_where_the_law_acts(comm):
    """A circle obstacle: the reported gap is the mean of g at the points, so u_ν − g reads the penetration the law
    sees (the nodes' own distance to the circle differs by the interpolation error of g)."""
    cfg = {**SCENES["2d"], "memory": {"kernel": "none"}, "damage": {"enabled": False}}
    cfg["boundary"] = {"top": {"role": "clamped"}, "bottom": {"role": "contact", "mu": MU,
                                  "obstacle": {"shape": "circle", "centre": [0.5, -1.0], "radius": 1.0}}}
    model = build_model(from_dict(cfg), comm)
    traces = model.mech.diagnostics.traces
    ds = model.geo.ds(model.geo.tags["bottom"], metadata={"quadrature_degree": 2})
    x = ufl.SpatialCoordinate(model.geo.mesh)
    g = ufl.sqrt((x[0] - 0.5) ** 2 + (x[1] + 1.0) ** 2) - 1.0
    total = comm.allreduce(fem.assemble_scalar(fem.form(g * ds)), op=MPI.SUM)
    on = traces.on[traces.on < traces.n_local]
    lumped = comm.allreduce(float(traces.mass[on] @ traces.gap.x.array[on]), op=MPI.SUM)
    assert lumped == pytest.approx(total, rel=1e-12)
    exact_at_nodes = np.hypot(traces.x[on, 0] - 0.5, traces.x[on, 1] + 1.0) - 1.0
    inner = (traces.x[on, 0] > 1e-12) & (traces.x[on, 0] < 1 - 1e-12)  # g convex: the mean over a whole hat is above
    assert np.all(traces.gap.x.array[on][inner] > exact_at_nodes[inner])


SHIPPED = {  # the shipped scenes, cut to a few levels (and coarser meshes where they are built in)
    "example1": ["mesh.nx=16", "mesh.ny=16", "time.T=0.05"],
    "example2": ["time.T=0.05"],
    "example3": ["time.T=0.05"],
    "hard": ["time.T=0.05"],
    "load_cycle": ["time.T=0.3", "time.k=0.05"],
    "example1_3d": ["mesh.nx=4", "mesh.ny=4", "mesh.nz=4", "time.T=0.06"],
}


@pytest.mark.parametrize("scene", sorted(SHIPPED))
def test_the_pressure_is_nonnegative_on_the_shipped_scenes(comm, scene):
    """At every level: the reported pressure >= -1e-8 x its peak over Γ_C (>= 0 by construction: λ_h dipped to −7%
    of the peak on Example 2), and its lumped integral is the contact force. scripts/contact_positivity.py runs the
    scenes whole, column3d too."""
    from solver.config import load
    from solver.run.stepper import levels
    from studies import REPO

    model = build_model(load(REPO / "configs" / f"{scene}.toml", SHIPPED[scene] + ["output.xdmf=false"]), comm)
    traces = model.mech.diagnostics.traces
    owned = traces.on[traces.on < traces.n_local]
    pressed = 0
    for row in levels(model):
        p = traces.pressure.x.array[owned]
        low = comm.allreduce(float(p.min()) if len(p) else np.inf, op=MPI.MIN)
        assert low >= -1e-8 * row["peak_pressure"]
        assert traces.lumped_force() == pytest.approx(row["contact_force"], rel=1e-12, abs=1e-300)
        pressed += row["peak_pressure"] > 0
    assert pressed > 0
