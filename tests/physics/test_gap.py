"""The gap as data (solver/physics/gap.py): the field is g exactly at the contact quadrature points, equal to the
old UFL ramps where those were exact, any number of rows, splines and analytic obstacles, and the config's
refusals."""

import numpy as np
import pytest
import ufl
from dolfinx import fem
from dolfinx.fem import petsc as fpetsc
from mpi4py import MPI
from petsc4py import PETSc

from solver.config import from_dict
from solver.config.boundary import AXES
from solver.errors import ConfigError
from solver.physics import contact
from solver.physics.gap import gap_function, gap_values, interpolation_error
from solver.run.model import build_model

STATIC = {"memory": {"kernel": "none"}, "damage": {"enabled": False}, "time": {"T": 1.0, "k": 1.0}}
# kinks between the vertices of a 10 x 10 mesh: the old ramps and the new field see them at the same points
TABLE = [[0.0, 0.002], [0.13, -0.001], [0.37, 0.0005], [0.61, -0.0015], [0.95, 0.001]]


def _old_ramps(part, mesh):
    """The gap as it was built before (a UFL sum of one clamped ramp per row), to compare with."""
    s = ufl.SpatialCoordinate(mesh)[AXES.index(part.gap_coordinate)]
    rows = part.gap_table
    g = rows[0][1]
    for (s0, g0), (s1, g1) in zip(rows, rows[1:]):
        g = g + (g1 - g0) / (s1 - s0) * (ufl.min_value(ufl.max_value(s, s0), s1) - s0)
    return g


def _model(comm, bottom: dict, n: int = 10, u_degree: int = 1):
    cfg = from_dict({**STATIC, "mesh": {"nx": n, "ny": n}, "discretization": {"u_degree": u_degree},
                     "boundary": {"top": {"role": "clamped"}, "bottom": {"role": "contact", "mu": 1e-3, **bottom}}})
    return build_model(cfg, comm)


def _assemble(model, gap) -> np.ndarray:
    """j(u, .) with the given gap expression, owned entries."""
    part = model.cfg.boundaries[-1]
    deg = model.cfg.solver.contact_quadrature_degree
    n = ufl.FacetNormal(model.geo.mesh)
    w = ufl.TestFunction(model.u.function_space)
    form = contact.compliance(contact.penetration(model.u, n, gap), part) * ufl.dot(w, n) * model.geo.ds(
        model.geo.tags[part.name], metadata={"quadrature_degree": deg})
    vec = fpetsc.assemble_vector(fem.form(form))
    vec.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
    return vec.array_r.copy()


@pytest.mark.parametrize("u_degree", [1, 2])
def test_table_field_is_the_old_ramps(comm, u_degree):
    """A linear table gives the contact term the old ramps gave, to 1e-12, with u pressed in everywhere."""
    model = _model(comm, {"gap": TABLE}, u_degree=u_degree)
    model.u.x.array[1::2] = -0.003
    part = model.cfg.boundaries[-1]
    new = _assemble(model, gap_function(part, model.geo, model.cfg.solver.contact_quadrature_degree))
    old = _assemble(model, _old_ramps(part, model.geo.mesh))
    scale = comm.allreduce(float(np.abs(old).max(initial=0.0)), op=MPI.MAX)
    assert scale > 0
    assert comm.allreduce(float(np.abs(new - old).max(initial=0.0)), op=MPI.MAX) <= 1e-12 * scale


def test_field_is_the_gap_at_the_contact_points(comm):
    """∫ g ds with the field equals Σ_q w_q g(x_q) over the contact points, for a 10^5-row table."""
    s = np.linspace(0.0, 1.0, 100_001)
    table = np.column_stack([s, 0.5 * (s - 0.4) ** 2 + 1e-4 * np.sin(300 * s)]).tolist()
    model = _model(comm, {"gap": table})
    part = model.cfg.boundaries[-1]
    deg = model.cfg.solver.contact_quadrature_degree
    g = gap_function(part, model.geo, deg)
    integral = comm.allreduce(fem.assemble_scalar(fem.form(g * model.geo.ds(
        model.geo.tags[part.name], metadata={"quadrature_degree": deg}))), op=MPI.SUM)
    pts = model.mech.diagnostics.points
    exact = comm.allreduce(float(pts.W @ gap_values(part, pts.x)), op=MPI.SUM)
    assert integral == pytest.approx(exact, rel=1e-13, abs=1e-16)
    assert np.array_equal(pts.g, gap_values(part, pts.x))


def test_spline_and_obstacles_at_points():
    """The cubic spline reproduces a cubic; the circle and the plane are signed distances."""
    from solver.config.boundary import BoundaryConfig

    s = np.linspace(0.0, 1.0, 7)
    cubic = BoundaryConfig("b", "contact", gap_table=tuple((a, a**3 - a) for a in s), gap_coordinate="x",
                           gap_interpolation="cubic")
    x = np.column_stack([np.linspace(-0.5, 1.5, 41), np.zeros(41), np.zeros(41)])
    xc = np.clip(x[:, 0], 0.0, 1.0)
    assert np.allclose(gap_values(cubic, x), xc**3 - xc, atol=1e-14)
    linear = BoundaryConfig("b", "contact", gap_table=cubic.gap_table, gap_coordinate="x")
    mid = 0.5 * (s[1:] + s[:-1])  # the chord's error at a midpoint is h^2 g''/8, g'' = 6 s
    assert interpolation_error(linear) == pytest.approx(np.max((s[1] - s[0]) ** 2 / 8 * 6 * mid), rel=1e-12)
    circle = BoundaryConfig("b", "contact", obstacle=(("shape", "circle"), ("centre", (0.5, -2.0)), ("radius", 2.0)))
    y = np.array([[0.5, 0.0, 0.0], [0.5, 0.1, 0.0], [2.5, -2.0, 0.0]])
    assert np.allclose(gap_values(circle, y), [0.0, 0.1, 0.0], atol=1e-15)
    plane = BoundaryConfig("b", "contact", obstacle=(("shape", "plane"), ("point", (0.0, -0.1)), ("normal", (1.0, 1.0))))
    assert np.allclose(gap_values(plane, y), (y[:, 0] + y[:, 1] + 0.1) / np.sqrt(2))


@pytest.mark.parametrize("bottom, key", [
    ({"gap": []}, "boundary.bottom.gap"),
    ({"gap": [[0.0, 0.0], [0.0, 1.0]]}, "boundary.bottom.gap"),
    ({"gap": [[0.0, 0.0], [1.0, float("nan")]]}, "boundary.bottom.gap[1][1]"),
    ({"gap": [[0.0, 0.0], [1.0, 0.0]], "gap_interpolation": "quintic"}, "boundary.bottom.gap_interpolation"),
    ({"gap": 0.0, "gap_interpolation": "cubic"}, "boundary.bottom.gap_interpolation"),
    ({"obstacle": {"shape": "sphere", "centre": [0, 0], "radius": 1.0}}, "boundary.bottom.obstacle.shape"),
    ({"obstacle": {"shape": "circle", "centre": [0, 0], "radius": -1.0}}, "boundary.bottom.obstacle.radius"),
    ({"obstacle": {"shape": "circle", "centre": [0, 0]}}, "boundary.bottom.obstacle.radius"),
    ({"obstacle": {"shape": "plane", "point": [0, 0], "normal": [0, 0]}}, "boundary.bottom.obstacle.normal"),
    ({"obstacle": {"shape": "circle", "centre": [0, 0], "radius": 1.0}, "gap": 0.1}, "boundary.bottom.obstacle"),
])
def test_bad_gaps_are_refused(bottom, key):
    with pytest.raises(ConfigError) as exc:
        from_dict({"boundary": {"left": {"role": "clamped"}, "bottom": {"role": "contact", **bottom}}})
    assert exc.value.key == key


@pytest.mark.parametrize("dim", [2, 3])
def test_obstacle_field_is_exact_at_the_quadrature_points(comm, dim):
    """∫ (g_field − g)² ds = 0 with the contact rule, g the circle's (sphere's) distance written in UFL: the
    field takes g's values at the very points FFCx integrates at, in 2-D and 3-D."""
    shape, centre = ("circle", [0.4, -2.0]) if dim == 2 else ("sphere", [0.4, 0.3, -2.0])
    mesh = {"nx": 6, "ny": 6} if dim == 2 else {"kind": "box", "corners": [[0, 0, 0], [1, 1, 1]], "nx": 3, "ny": 3,
                                                "nz": 3}
    extra = {"material": {"model": "3d"}} if dim == 3 else {}
    cfg = from_dict({**STATIC, **extra, "mesh": mesh, "boundary": {
        "top": {"role": "clamped"},
        "bottom": {"role": "contact", "obstacle": {"shape": shape, "centre": centre, "radius": 2.0}}}})
    model = build_model(cfg, comm)
    part = model.cfg.boundaries[-1]
    deg = model.cfg.solver.contact_quadrature_degree
    x = ufl.SpatialCoordinate(model.geo.mesh)
    c = ufl.as_vector(centre)
    exact = ufl.sqrt(ufl.dot(x - c, x - c)) - 2.0
    ds = model.geo.ds(model.geo.tags[part.name], metadata={"quadrature_degree": deg})
    g = gap_function(part, model.geo, deg)
    diff = comm.allreduce(fem.assemble_scalar(fem.form((g - exact) ** 2 * ds)), op=MPI.SUM)
    size = comm.allreduce(fem.assemble_scalar(fem.form(exact**2 * ds)), op=MPI.SUM)
    assert size > 0
    assert diff <= 1e-26 * size
    # and not merely close: the DG interpolant at its own nodes would be off by O(h^2) g''
    off = comm.allreduce(fem.assemble_scalar(fem.form((g - exact) ** 2 * model.geo.ds(
        model.geo.tags[part.name], metadata={"quadrature_degree": deg + 3}))), op=MPI.SUM)
    assert off > 1e6 * diff


def test_a_table_coarser_than_the_law_warns_in_one_line(caplog):
    """The issue's case: g = x^2/2R (R = 1) every 0.002 under mu = 1e-8 at p = 2.8: error s^2/8 = 5e-7 is 18 times
    mu p = 2.8e-8: one line; every 1e-5 (error 1.25e-11) nothing."""
    from solver.config.boundary import BoundaryConfig
    from solver.physics.diagnostics import _warn_coarse_tables, allowed_penetration

    def part(ds, name):
        s = np.arange(0.0, 0.3 + ds / 2, ds)
        return BoundaryConfig(name, "contact", mu=1e-8, gap_table=tuple((a, a * a / 2) for a in s),
                              gap_coordinate="x")

    coarse, fine = part(0.002, "bottom"), part(1e-5, "side")
    errors = {p.name: interpolation_error(p) for p in (coarse, fine)}
    assert allowed_penetration(coarse, 2.8) == pytest.approx(2.8e-8)
    assert interpolation_error(coarse) == pytest.approx(0.002**2 / 8, rel=1e-6)
    with caplog.at_level("WARNING", logger="solver"):
        _warn_coarse_tables((coarse, fine), errors, 2.8)
    assert len(caplog.records) == 1 and "\n" not in caplog.records[0].getMessage()
    assert "boundary.bottom" in caplog.records[0].getMessage() and "18 times" in caplog.records[0].getMessage()
    caplog.clear()
    with caplog.at_level("WARNING", logger="solver"):
        _warn_coarse_tables((fine,), errors, 2.8)
    assert not caplog.records
