"""Pictures of a results directory (``python -m solver plot DIR``), read from what the run wrote
(``solution.xdmf`` and the data it points to).

- ``von_mises_elastic_{initial,final}.png``: the von Mises norm of A eps(u) over the deformed
  configuration (warp factor in the title), like the paper's Figs. 5 and 8, and
  ``von_mises_{initial,final}.png`` for the total stress sigma;
- ``damage_final.png``: the damage at the final time (Figs. 6 and 9);
- ``timeseries.png``: contact force, minimum damage and ||eps(u)|| against time;
- ``contact_<part>.png`` (scenes with contact, from ``contact.csv``): in 2-D the pressure along the part at every
  written level, coloured by t (a colour bar for t), the contact zone (p > 0) of the last one shaded, and below
  it the gap g and the normal displacement u_ν at the last time; in 3-D a map of the contact face at the last
  level, seen head-on, the pressure as colour and the contact zone's outline (p = 0).

Each picture has its own colour range (its minimum to its maximum, as the bar shows) and flat colours (no lighting),
so that a pixel's colour is the colour bar's at its value. The displacement is drawn x w, the same w in every
picture of a run and in ``solver paraview``'s (:func:`auto_warp`). Lengths and stresses are in the scene's units, which the
solver does not know: the axes say "(model units)".
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from solver.errors import UsageError
from solver.io.layout import ResultsDir, check_writable
from solver.post.charts import pyplot
from solver.post.results import read_csv, read_profile, read_results  # no dolfinx here: VTK and dolfinx's C++ do not mix


def _pyvista():
    """pyvista, off screen, with VTK's log at errors only (without an X server VTK warns, in ANSI yellow, before it
    renders anyway)."""
    import pyvista as pv
    from vtkmodules.vtkCommonCore import vtkLogger

    vtkLogger.SetStderrVerbosity(vtkLogger.VERBOSITY_ERROR)
    pv.OFF_SCREEN = True
    return pv


def _pyplot(what: str):
    """matplotlib's pyplot off screen; a one-line error where the plotting extra is missing."""
    plt = pyplot(what)
    if plt is None:
        raise UsageError(f"{what} needs matplotlib: make install PLOTS=1")
    return plt


def _grid(res: dict, t: float, warp: float):
    pv = _pyvista()
    x = np.zeros((res["geometry"].shape[0], 3))
    x[:, : res["geometry"].shape[1]] = res["geometry"]
    u = res["fields"].get("displacement", {}).get(t)  # no displacement written: the undeformed body
    if u is not None:
        x[:, : u.shape[1]] += warp * u[:, : x.shape[1]]
    cells = res["topology"]
    kind = {3: pv.CellType.TRIANGLE, 4: pv.CellType.TETRA}[cells.shape[1]]
    conn = np.hstack([np.full((len(cells), 1), cells.shape[1]), cells]).ravel()
    return pv.UnstructuredGrid(conn, np.full(len(cells), kind, dtype=np.uint8), x)


WARP_LEVELS = 21  # the levels the automatic warp looks at: all of a short series, 21 evenly spaced of a longer one


def warp_levels(n: int) -> list[int]:
    """Indices of the written levels (of ``n``) whose displacement sets the automatic warp: all up to 21, else 21
    evenly spaced, first and last included (``solver paraview`` reads the same ones: paraview_script.warp_levels)."""
    return sorted({round(i * (n - 1) / (WARP_LEVELS - 1)) for i in range(WARP_LEVELS)}) if n > WARP_LEVELS else \
        list(range(n))


def auto_warp(res: dict) -> float:
    """The largest displacement component over the written levels (:func:`warp_levels`) drawn as 10 % of the body's
    size, rounded down to 1, 2 or 5 x 10^m: one factor for every picture of a run, the same as ``solver paraview``'s
    default (paraview_script.nice_warp)."""
    size = np.ptp(res["geometry"], axis=0).max()
    levels = res["fields"].get("displacement", {})
    times = sorted(levels)
    tops = [_finite_max(np.abs(levels[times[i]])) for i in warp_levels(len(times))]
    umax = max((m for m in tops if np.isfinite(m)), default=0.0)
    if not umax > 0:  # nothing moves (or no displacement was written, or none of it is finite)
        return 1.0
    w = 0.1 * size / umax
    e = 10 ** np.floor(np.log10(w))
    return float(max(m for m in (1, 2, 5) if m * e <= w * (1 + 1e-12)) * e)


def _finite_max(values: np.ndarray) -> float:
    """The largest finite value (nan if there is none): a damaged or diverged field still draws."""
    finite = values[np.isfinite(values)]
    return float(finite.max()) if finite.size else float("nan")


def _range(values: np.ndarray, clim):
    """The colour range, and a note for the title: a constant field gets a range around its value (a zero-width
    one draws it in the colour map's end colour, black for magma, and hides the bar's ticks)."""
    finite = values[np.isfinite(values)]
    if clim is None or not np.isfinite(clim).all():
        clim = (float(finite.min()), float(finite.max())) if finite.size else (0.0, 0.0)
    lo, hi = clim
    if hi - lo > 1e-12 * max(abs(lo), abs(hi), 1e-300):
        return (lo, hi), ""
    v = float(np.mean(finite)) if finite.size else 0.0
    pad = 0.5 * abs(v) if v else 1.0
    return (v - pad, v + pad), f" -- constant: {v:.6g} everywhere"


def number_format(lo: float, hi: float) -> str:
    """A printf format with enough significant digits that the ends of [lo, hi] and the ticks between differ
    (3, more for a narrow range far from 0: damage from 0.9986 to 0.9999)."""
    span, mag = abs(hi - lo), max(abs(lo), abs(hi))
    digits = 3 if not (span > 0 and mag > 0) else max(3, int(np.ceil(np.log10(mag / span))) + 2)
    return f"%.{min(digits, 10)}g"


BAR_TITLES = {"damage": "damage zeta\n(dimensionless)", "von_mises_elastic": "von Mises A eps(u)\n(model units)",
              "von_mises": "von Mises sigma\n(model units)"}


def render(res: dict, field: str, t: float, warp: float, path: Path, title: str, clim=None, cmap="viridis") -> None:
    """``field`` at level ``t`` over the body warped by ``warp``, unlit (a pixel's colour is the bar's at its value),
    coloured over ``clim`` (default: this picture's minimum to maximum; a shared range is the caller's to state)."""
    pv = _pyvista()
    grid = _grid(res, t, warp)
    values = res["fields"][field][t]
    if values.ndim > 1:
        values = values[:, 0]
    clim, note = _range(values, clim)
    title += note
    if len(values) == grid.n_cells:
        grid.cell_data[field] = values
    else:
        grid.point_data[field] = values
    outline = _grid(res, t, 0.0)
    solid = res["topology"].shape[1] == 4
    if solid:  # 3-D: the body's edges (30-degree feature edges of its surface), seen from above a corner
        edges = outline.extract_surface(algorithm="dataset_surface").extract_feature_edges(feature_angle=30, boundary_edges=False,
                                                                 feature_edges=True, manifold_edges=False)
    else:
        edges = outline.extract_feature_edges(boundary_edges=True, feature_edges=False, manifold_edges=False)
    p = pv.Plotter(off_screen=True, window_size=(900, 650))
    p.add_mesh(edges, color="gray", line_width=1, lighting=False)
    bar = BAR_TITLES.get(field, field.replace("_", " ") + "\n(model units)")
    fmt = number_format(*clim)
    p.add_mesh(grid, scalars=field, cmap=cmap, clim=clim, show_edges=False, lighting=False,
               # the bar at the right edge, beside the body (not over its contact edge), its title above it
               scalar_bar_args={"title": bar + "\n", "vertical": True, "fmt": fmt, "color": "black",
                                "position_x": 0.84, "position_y": 0.12, "width": 0.08, "height": 0.7,
                                "title_font_size": 16, "label_font_size": 14})
    p.set_background("white")
    p.add_text(f"{title}\nt = {t:g}, displacement x {warp:g} (grey: undeformed); "
               f"colours from {fmt % clim[0]} to {fmt % clim[1]}", font_size=10, color="black")
    axes = {"xtitle": "x (model units)", "ytitle": "y (model units)", "ztitle": "z (model units)", "color": "black",
            "font_size": 10, "fmt": "%.2g"}
    if solid:
        p.show_bounds(mesh=outline, location="outer", **axes)
        p.view_isometric()
        p.camera.zoom(0.85)  # the whole body, clear of the colour bar at the right
    else:
        p.show_bounds(mesh=outline, location="outer", show_zaxis=False, show_zlabels=False, **axes)
        p.view_xy()
        p.camera.zoom(1.0)
        # move the body left of the bar: the camera looks at a point right of the body's centre
        (x0, x1, *_), cam = grid.bounds, p.camera
        dx = 0.12 * (x1 - x0)
        cam.focal_point = (cam.focal_point[0] + dx, cam.focal_point[1], cam.focal_point[2])
        cam.position = (cam.position[0] + dx, cam.position[1], cam.position[2])
    p.screenshot(str(path))
    p.close()


def timeseries(rows: list[dict], path: Path) -> None:
    plt = _pyplot("the time-series chart")

    t = [r["t"] for r in rows]
    fig, axes = plt.subplots(1, 3, figsize=(13, 3.6))
    for ax, key, label in zip(axes, ("contact_force", "zeta_min", "strain_norm"),
                              ("contact force  $\\int_{\\Gamma_C} p\\,ds$", "min damage $\\zeta$",
                               "$\\|\\varepsilon(u)\\|_{L^2}$")):
        ax.plot(t, [r[key] for r in rows], "-")
        ax.set_xlabel("t")
        ax.set_title(label)
        ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


PRESSURE_LABEL = "contact pressure p (model units)"


def contact_profiles(profile: dict, out: Path, dim: int = 2) -> list[Path]:
    """One picture per contact part from :func:`read_profile`'s dict: in 2-D (``dim``) the pressure along the part
    at every written level coloured by t, in 3-D a map of the face at the last level (:func:`contact_map`)."""
    plt = _pyplot("the contact profile chart")
    made = []
    for part in sorted({name for _, name in profile}):
        steps = sorted(step for step, name in profile if name == part)
        fig = contact_map(plt, profile[(steps[-1], part)], part) if dim == 3 else _profile(plt, profile, steps, part)
        path = out / f"contact_{part}.png"
        fig.savefig(path, dpi=110)
        plt.close(fig)
        made.append(path)
    return made


def _profile(plt, profile: dict, steps: list[int], part: str):
    """p(s) at every written level, a line a level coloured by its t (a colour bar for t), the last level's contact
    zone shaded; below, the gap and u_ν at the last level."""
    from matplotlib.collections import LineCollection

    levels = [profile[(step, part)] for step in steps]
    times = np.array([lv["t"][0] for lv in levels])
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(7.5, 6.4), sharex=True, gridspec_kw={"height_ratios": (3, 2)})
    norm = plt.Normalize(times.min(), times.max() if times.max() > times.min() else times.min() + 1.0)
    lines = LineCollection([np.column_stack([lv["s"], lv["pressure"]]) for lv in levels], cmap="viridis",
                           norm=norm, linewidths=1.2)
    lines.set_array(times)
    last = levels[-1]
    active = last["penetration"] > 0
    if active.any():  # the zone of the last level: the segments between its active nodes (a node out of it breaks it)
        top.fill_between(last["s"], 0, 1, where=active, transform=top.get_xaxis_transform(), color="0.88",
                         zorder=0, linewidth=0, label=f"contact zone (p > 0) at t = {times[-1]:g}")
        top.legend(fontsize=8, loc="upper right")
    top.add_collection(lines)
    top.autoscale_view()
    bar = fig.colorbar(lines, ax=[top, bottom], pad=0.02, aspect=30)
    bar.set_label("t (model units)")
    top.set_ylabel(PRESSURE_LABEL)
    top.set_title(f"Contact pressure on boundary '{part}' at {len(levels)} written levels")
    bottom.plot(last["s"], last["gap"], "k-", label="gap g")
    bottom.plot(last["s"], last["u_normal"], "--", color="tab:red", label="normal displacement $u_\\nu$")
    bottom.set_title(f"at t = {times[-1]:g}", fontsize=10)
    bottom.set_xlabel(f"arc length s along '{part}' (model units)")
    bottom.set_ylabel("g, $u_\\nu$ (model units)")
    bottom.legend(fontsize=8)
    for ax in (top, bottom):
        ax.grid(alpha=0.3)
    return fig


def face_coordinates(points: np.ndarray) -> tuple[np.ndarray, tuple[str, str]]:
    """The face's points in two coordinates of its plane, and their axis labels: the two coordinate axes the
    face spans when it lies in a plane x, y or z = const, else its two principal directions."""
    centred = points - points.mean(axis=0)
    _, _, vt = np.linalg.svd(centred, full_matrices=False)
    normal = vt[-1]
    k = int(np.argmax(np.abs(normal)))
    if abs(normal[k]) > 1 - 1e-9:  # an axis-aligned face: its own coordinates
        i, j = (a for a in range(3) if a != k)
        return points[:, [i, j]], tuple(f"{'xyz'[a]} (model units)" for a in (i, j))
    return centred @ vt[:2].T, ("first in-plane direction (model units)", "second in-plane direction (model units)")


def contact_map(plt, level: dict, part: str):
    """The contact face seen head-on: the pressure as colour (Gouraud-interpolated between the nodes, unlit), the
    contact zone's outline (p = 0) in black."""
    import matplotlib.tri as mtri

    xy, labels = face_coordinates(np.column_stack([level["x"], level["y"], level["z"]]))
    tri = mtri.Triangulation(xy[:, 0], xy[:, 1])
    fig, ax = plt.subplots(figsize=(7.2, 6.0))
    pressure = level["pressure"]
    lo, hi = _range(pressure, None)[0]
    shaded = ax.tripcolor(tri, pressure, shading="gouraud", cmap="viridis", vmin=lo, vmax=hi)
    bar = fig.colorbar(shaded, ax=ax, pad=0.02)
    bar.set_label(PRESSURE_LABEL)
    pen = level["penetration"]
    note = "no node in contact"
    if (pen > 0).any() and (pen <= 0).any():
        ax.tricontour(tri, pen, levels=[0.0], colors="black", linewidths=1.5)
        note = "black: the contact zone's edge (p = 0)"
    elif (pen > 0).all():
        note = "the whole face in contact"
    ax.plot(xy[:, 0], xy[:, 1], ".", color="0.3", ms=2)
    ax.set_aspect("equal")
    ax.set_xlabel(labels[0])
    ax.set_ylabel(labels[1])
    ax.set_title(f"Contact pressure on face '{part}' at t = {level['t'][0]:g}\n({note}; dots: nodes)", fontsize=11)
    fig.tight_layout()
    return fig


def plot_results(directory: str | Path, warp: float | None = None, out: str | Path | None = None,
                 extra_times: tuple[float, ...] = ()) -> list[Path]:
    """Write the PNGs of a results directory (plus von Mises at ``extra_times``); returns their paths. Everything is
    read (and a damaged file refused, :class:`ResultsError`) before the first picture is written."""
    directory = Path(directory)
    out = Path(out) if out else directory
    res = read_results(directory)
    rows, profile = _read_tables(directory)
    nearest = [_nearest_level(res["times"], t) for t in extra_times]  # refused before anything is drawn
    check_writable(out, f"--output {out}" if out != directory else f"{directory} (give --output elsewhere)")
    w = warp if warp is not None else auto_warp(res)
    made = []
    for field, what in (("von_mises_elastic", "A eps(u)"), ("von_mises", "sigma = A eps(u) + memory")):
        if not res["fields"].get(field):
            continue
        vm = res["fields"][field]
        written = sorted(vm)  # the levels that hold the field (a restart may change output.fields)
        picks = [("initial", written[0]), ("final", written[-1])]
        for near in nearest:
            if near in vm:
                picks.append((f"t{near:g}".replace(".", "_"), near))
        for label, t in picks:
            path = out / f"{field}_{label}.png"
            render(res, field, t, w, path, f"von Mises norm of {what} ({label})", cmap="turbo")
            made.append(path)
    if res["fields"].get("damage"):
        path = out / "damage_final.png"
        render(res, "damage", max(res["fields"]["damage"]), w, path, "damage zeta (final)", cmap="magma")
        made.append(path)
    if rows is not None:
        path = out / "timeseries.png"
        timeseries(rows, path)
        made.append(path)
    if profile is not None:
        made += contact_profiles(profile, out, dim=3 if res["topology"].shape[1] == 4 else 2)
    return made


TIMESERIES_COLUMNS = ("t", "contact_force", "zeta_min", "strain_norm")


def _read_tables(directory: Path) -> tuple[list[dict] | None, dict | None]:
    """timeseries.csv's rows and contact.csv's profiles (None where the file is absent), read before any picture."""
    files = ResultsDir(directory)
    csv_path, contact = files.timeseries, files.contact
    rows = read_csv(csv_path, need=TIMESERIES_COLUMNS) if csv_path.exists() else None
    return rows, (read_profile(contact) if contact.exists() else None)


def _nearest_level(times: list[float], t: float) -> float:
    """The written level nearest to t (said on stderr when it is not t); a t outside the written levels'
    span [t_0, t_last] is a UsageError."""
    if not (times[0] <= t <= times[-1]):
        raise UsageError(f"--times {t:g}: outside the written levels, which span [{times[0]:g}, {times[-1]:g}]")
    near = min(times, key=lambda s: abs(s - t))
    if near != t:
        print(f"note: --times {t:g}: no level written at that time; drawn at the nearest written level, "
              f"t = {near:g}", file=sys.stderr)
    return near


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="solver plot", description="PNG pictures of a results directory")
    p.add_argument("directory")
    p.add_argument("--warp", type=float, default=None, help="displacement scale (default: automatic, stated in the title)")
    p.add_argument("--output", default=None, help="where to write the PNGs (default: the results directory)")
    p.add_argument("--times", type=float, nargs="*", default=[], help="also draw von Mises at these written times")
    args = p.parse_args(argv)
    if not (Path(args.directory) / "solution.xdmf").exists():
        print(f"error: {args.directory}: no solution.xdmf (is it a results directory?)", file=sys.stderr)
        return 2
    try:
        made = plot_results(args.directory, args.warp, args.output, tuple(args.times))
    except UsageError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    for path in made:
        print(path)
    return 0
