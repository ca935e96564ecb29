"""Pictures of a results directory (``python -m solver plot DIR``), read from what the run wrote
(``solution.xdmf`` and the data it points to).

- ``von_mises_elastic_{initial,final}.png``: the von Mises norm of A eps(u) over the deformed
  configuration (warp factor in the title), like the paper's Figs. 5 and 8, and
  ``von_mises_{initial,final}.png`` for the total stress sigma;
- ``damage_final.png``: the damage at the final time (Figs. 6 and 9);
- ``timeseries.png``: contact force, minimum damage and ||eps(u)|| against time;
- ``contact_<part>.png`` (scenes with contact, from ``contact.csv``): the pressure λ_h along the part at
  the written times (up to six), the contact zone (u_ν > g) of the last one shaded, and below it the gap g
  and the normal displacement u_ν at the last time.
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


def auto_warp(res: dict) -> float:
    """Largest displacement drawn as 10 % of the body's size (rounded to 1, 2 or 5 x 10^m)."""
    size = np.ptp(res["geometry"], axis=0).max()
    tops = [_finite_max(np.abs(v)) for v in res["fields"].get("displacement", {}).values()]
    umax = max((m for m in tops if np.isfinite(m)), default=0.0)
    if not umax > 0:  # nothing moves (or no displacement was written, or none of it is finite)
        return 1.0
    w = 0.1 * size / umax
    e = 10 ** np.floor(np.log10(w))
    return float(max(m for m in (1, 2, 5) if m * e <= w) * e)


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


def render(res: dict, field: str, t: float, warp: float, path: Path, title: str, clim=None, cmap="viridis") -> None:
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
        edges = outline.extract_surface().extract_feature_edges(feature_angle=30, boundary_edges=False,
                                                                 feature_edges=True, manifold_edges=False)
    else:
        edges = outline.extract_feature_edges(boundary_edges=True, feature_edges=False, manifold_edges=False)
    p = pv.Plotter(off_screen=True, window_size=(900, 650))
    p.add_mesh(edges, color="gray", line_width=1)
    p.add_mesh(grid, scalars=field, cmap=cmap, clim=clim, show_edges=False,
               # the bar at the right edge, beside the body (not over its contact edge), its title above it
               scalar_bar_args={"title": field.replace("_", " ") + "\n", "vertical": True, "fmt": "%.3g",
                                "position_x": 0.86, "position_y": 0.15, "width": 0.08, "height": 0.7})
    p.add_text(f"{title}\nt = {t:g}, displacement x {warp:g} (grey: undeformed)", font_size=11)
    if solid:
        p.view_isometric()
        p.camera.zoom(0.9)  # the whole body, clear of the colour bar at the right
    else:
        p.view_xy()
        p.camera.zoom(1.1)
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


def contact_profiles(profile: dict, out: Path) -> list[Path]:
    """p(s) at the written levels per contact part (:func:`read_profile`'s dict), the last one's zone shaded."""
    plt = _pyplot("the contact profile chart")
    made = []
    for part in sorted({name for _, name in profile}):
        steps = sorted(step for step, name in profile if name == part)
        picks = [steps[i] for i in np.unique(np.linspace(0, len(steps) - 1, min(6, len(steps))).round().astype(int))]
        fig, (top, bottom) = plt.subplots(2, 1, figsize=(7, 6), sharex=True)
        for step in picks:
            p = profile[(step, part)]
            top.plot(p["s"], p["pressure"], "-", label=f"t = {p['t'][0]:g}")
        last = profile[(picks[-1], part)]
        active = last["penetration"] > 0
        if active.any():  # the zone of the last level: the span of its active nodes
            top.axvspan(last["s"][active].min(), last["s"][active].max(), color="0.9", zorder=0,
                        label="contact zone (last t)")
        top.set_ylabel("contact pressure $\\lambda_h$")
        top.set_title(f"boundary.{part}")
        top.legend(fontsize=8)
        bottom.plot(last["s"], last["gap"], "k-", label="gap g")
        bottom.plot(last["s"], last["u_normal"], "--", label=f"$u_\\nu$ (t = {last['t'][0]:g})")
        bottom.set_xlabel("s along the part")
        bottom.legend(fontsize=8)
        for ax in (top, bottom):
            ax.grid(alpha=0.3)
        fig.tight_layout()
        path = out / f"contact_{part}.png"
        fig.savefig(path, dpi=110)
        plt.close(fig)
        made.append(path)
    return made


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
        tops = [m for m in map(_finite_max, vm.values()) if np.isfinite(m)]
        clim = (0.0, max(tops, default=float("nan")))  # one colour scale for both times (nan: from the values)
        written = sorted(vm)  # the levels that hold the field (a restart may change output.fields)
        picks = [("initial", written[0]), ("final", written[-1])]
        for near in nearest:
            if near in vm:
                picks.append((f"t{near:g}".replace(".", "_"), near))
        for label, t in picks:
            path = out / f"{field}_{label}.png"
            render(res, field, t, w, path, f"von Mises norm of {what} ({label})", clim=clim, cmap="turbo")
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
        made += contact_profiles(profile, out)
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
