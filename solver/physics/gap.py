"""The gap g of a contact part as data: evaluated by numpy at points, and as a field that is g exactly at the
contact quadrature points (docs/contact.md).

g is one of
- a number (``gap``);
- a table of rows (s, g) in the coordinate ``gap_coordinate``, interpolated ``linear`` (piecewise linear,
  the default) or ``cubic`` (a C² not-a-knot cubic spline through the rows), held constant beyond the table;
- an analytic rigid obstacle (``obstacle``): a ``plane`` through ``point`` with unit ``normal`` pointing
  into the body, g(x) = n·(x − p); a ``circle`` (2-D) or ``sphere`` (3-D) of ``radius`` R and ``centre`` c
  outside which the body lies, g(x) = |x − c| − R: the signed distance from the point to the surface,
  as Abaqus's analytical rigid surfaces measure it (closest point).

In the UFL terms a non-constant g is a discontinuous Lagrange function of degree k, filled once per run:
on each cell with a contact facet its values are the polynomial that takes g's values at the facet
quadrature points (mapped as FFCx maps them: the reference facet's rule onto the reference cell's facet),
so the form sees g exactly at its points, at a cost independent of the table's rows (a UFL sum of one clamped
ramp per row would exceed UFL's recursion limit at some thousand rows).
"""

from __future__ import annotations

import weakref

import basix
import numpy as np
from dolfinx import fem

from solver.config import BoundaryConfig
from solver.config.boundary import AXES
from solver.config.tables import as_array
from solver.physics.quadrature import ContactRule, contact_rule


def gap_values(part: BoundaryConfig, x: np.ndarray) -> np.ndarray:
    """g at points x (n, 3 or gdim): the part's number, table or obstacle."""
    x = np.asarray(x, dtype=float)  # (n, 3) or (n, gdim); n may be 0 on a rank without the part
    if part.obstacle:
        return _obstacle(part, x)
    if not part.gap_table:
        return np.full(len(x), part.gap)
    s = x[:, AXES.index(part.gap_coordinate)]
    rows = as_array(part.gap_table)
    if part.gap_interpolation == "cubic" and len(rows) > 2:
        return _spline(part.gap_table)(np.clip(s, rows[0, 0], rows[-1, 0]))
    return np.interp(s, rows[:, 0], rows[:, 1])  # constant beyond the ends, as the table was


_SPLINES: dict = {}


def _spline(table: tuple):
    """The not-a-knot cubic spline through a table (built once per table)."""
    from scipy.interpolate import CubicSpline

    key = id(table)  # by identity, as gap_function's cache
    if key not in _SPLINES or _SPLINES[key][0] is not table:
        rows = as_array(table)
        _SPLINES[key] = (table, CubicSpline(rows[:, 0], rows[:, 1]))
    return _SPLINES[key][1]


def _obstacle(part: BoundaryConfig, x: np.ndarray) -> np.ndarray:
    """Signed distance from x to the obstacle's surface (> 0: apart)."""
    ob = dict(part.obstacle)
    d = x.shape[1]
    if ob["shape"] == "plane":
        p, n = np.zeros(d), np.zeros(d)
        p[: len(ob["point"])], n[: len(ob["normal"])] = ob["point"], ob["normal"]
        return (x - p) @ (n / np.linalg.norm(n))
    c = np.zeros(d)
    c[: len(ob["centre"])] = ob["centre"]
    return np.linalg.norm(x - c, axis=1) - ob["radius"]


def segment_errors(part: BoundaryConfig) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Per segment [s_i, s_i+1] of a linear gap table: (s_i, s_i+1, min(g_i, g_i+1), error), the error an estimate of
    how far the chord is from the smooth profile the rows sample: h² |g''(mid)| / 8, with g'' the rows' second
    divided differences (each g'' at the mean of its three abscissae) interpolated linearly to the segment's midpoint,
    extrapolated at the ends (exact for a cubic profile, any spacing). Empty if not a linear table of 4 rows or more.
    Numpy only: O(rows), and no scipy to import."""
    rows = as_array(part.gap_table) if part.gap_table else np.zeros((0, 2))
    if len(rows) < 4 or part.gap_interpolation != "linear" or part.obstacle:
        empty = np.zeros(0)
        return empty, empty, empty, empty
    s, g = rows[:, 0], rows[:, 1]
    h = np.diff(s)
    slope = np.diff(g) / h
    d2 = 2.0 * np.diff(slope) / (s[2:] - s[:-2])  # g'' at c_i = (s_i-1 + s_i + s_i+1) / 3, exact for a cubic
    c = (s[:-2] + s[1:-1] + s[2:]) / 3.0
    mid = 0.5 * (s[1:] + s[:-1])
    j = np.clip(np.searchsorted(c, mid) - 1, 0, len(c) - 2)  # the pair of c around (or next to) each midpoint
    w = (mid - c[j]) / (c[j + 1] - c[j])
    curvature = (1.0 - w) * d2[j] + w * d2[j + 1]
    return s[:-1], s[1:], np.minimum(g[1:], g[:-1]), h * h * np.abs(curvature) / 8.0


def interpolation_error(part: BoundaryConfig) -> float:
    """Largest :func:`segment_errors` over the whole table (~ max s_i² |g''| / 8); 0 if not a linear table."""
    err = segment_errors(part)[3]
    return float(err.max()) if len(err) else 0.0


class ReachableError:
    """The largest interpolation error of a linear gap table over the segments the body can reach: those within the
    part's extent ``[lo, hi]`` along the table's coordinate whose lower end's gap is at most a given gap (the largest
    gap under the contact zone): :meth:`up_to` answers in O(log rows)."""

    def __init__(self, part: BoundaryConfig, lo: float, hi: float) -> None:
        s0, s1, gmin, err = segment_errors(part)
        inside = (s1 >= lo) & (s0 <= hi)
        order = np.argsort(gmin[inside], kind="stable")
        self.gmin = gmin[inside][order]
        self.cummax = np.maximum.accumulate(err[inside][order]) if len(order) else np.zeros(0)

    def up_to(self, g: float) -> float:
        """Largest error over the reachable segments whose lower gap is <= g (0 if none)."""
        i = int(np.searchsorted(self.gmin, g, side="right"))
        return float(self.cummax[i - 1]) if i > 0 else 0.0


def varying(part: BoundaryConfig) -> bool:
    """Whether the part's gap depends on the point (a table or an obstacle)."""
    return bool(part.gap_table) or bool(part.obstacle)


_FIELDS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def gap_function(part: BoundaryConfig, geo, degree: int | ContactRule) -> float | fem.Function:
    """The part's gap for UFL: its number, or a DG field equal to g at the part's facet points of the contact rule
    (a Gauss degree or a :class:`~solver.physics.quadrature.ContactRule`; built once per mesh, part and rule)."""
    if not varying(part):
        return part.gap
    rule = contact_rule(degree)
    cache = _FIELDS.setdefault(geo.mesh, {})
    key = (id(part), rule)  # by identity: hashing a part hashes its table (10⁵ rows: 0.2 s)
    if key not in cache or cache[key][0] is not part:
        cache[key] = (part, _fill(part, geo, rule))
    return cache[key][1]


def _monomials(X: np.ndarray, k: int) -> np.ndarray:
    """All monomials of total degree <= k at reference points X (n, tdim)."""
    tdim = X.shape[1]
    powers = [p for p in np.ndindex(*(k + 1,) * tdim) if sum(p) <= k]
    return np.stack([np.prod(X ** np.array(p), axis=1) for p in powers], axis=1)


def _field_degree(tdim: int, npts: int) -> int:
    """A DG degree whose traces can take any values at one facet's npts points, with room for a second facet."""
    if tdim == 2:
        return npts
    k = 1
    while (k + 1) * (k + 2) // 2 < npts:
        k += 1
    return k + 1


def _fill(part: BoundaryConfig, geo, rule: ContactRule) -> fem.Function:
    """The DG field: per cell with facets of the part, the polynomial of least coefficients through g at their points."""
    mesh = geo.mesh
    tdim, fdim = mesh.topology.dim, mesh.topology.dim - 1
    cell_type = {2: basix.CellType.triangle, 3: basix.CellType.tetrahedron}[tdim]
    facet_type = {2: basix.CellType.interval, 3: basix.CellType.triangle}[tdim]
    points, _ = rule.facet_quadrature(facet_type)
    k = _field_degree(tdim, len(points))
    W = fem.FunctionSpace(mesh, ("DG", k))
    g = fem.Function(W, name=f"gap_{part.name}")
    ref_vertices = basix.geometry(cell_type)
    ref_facets = basix.topology(cell_type)[fdim]
    on_facet = []  # the rule's points on each reference facet, in reference cell coordinates
    for vs in ref_facets:
        v = ref_vertices[vs]
        on_facet.append(v[0] + points @ (v[1:] - v[0]))
    nodes = _monomials(np.asarray(W.element.interpolation_points()), k)  # DG dof i = value at node i
    mesh.topology.create_connectivity(fdim, tdim)
    mesh.topology.create_connectivity(tdim, fdim)
    f2c, c2f = mesh.topology.connectivity(fdim, tdim), mesh.topology.connectivity(tdim, fdim)
    xg, gdofs = mesh.geometry.x, mesh.geometry.dofmap
    cells: dict[int, list[int]] = {}
    for f in geo.facets(part.name):
        c = int(f2c.links(f)[0])
        cells.setdefault(c, []).append(int(np.flatnonzero(c2f.links(c) == f)[0]))
    refs, xs = [], []
    for c, local in cells.items():
        X = np.concatenate([on_facet[i] for i in local])
        xc = xg[gdofs.links(c)]
        refs.append(X)
        xs.append(xc[0] + X @ (xc[1 : tdim + 1] - xc[0]))  # affine simplices
    values = gap_values(part, np.concatenate(xs)) if xs else np.zeros(0)  # one pass over the table
    start = 0
    for c, X in zip(cells, refs):
        coeffs = np.linalg.lstsq(_monomials(X, k), values[start : start + len(X)], rcond=None)[0]
        start += len(X)
        g.x.array[W.dofmap.cell_dofs(c)] = nodes @ coeffs
    return g
