"""Render a results directory with ParaView: run me with ``pvbatch`` (or ``pvpython``), not with the solver's Python.

    pvbatch --force-offscreen-rendering solver/post/paraview_script.py RESULTS_DIR [--field von_mises_elastic] [--time T]
        [--warp W] [--output PNG] [--size 1200 800]

(``python -m solver paraview RESULTS_DIR ...`` does this for you, under ``xvfb-run`` when there is no display.)

The pipeline is the one a user builds in the GUI: open ``solution.xdmf`` (reader ``Xdmf3ReaderS``), go to a time,
Warp By Vector with ``displacement``, colour by a cell (or point) field, plus a scalar bar, a caption and the undeformed
boundary in grey (in 3-D: the surface's 30-degree feature edges); then a camera fitting the body (2-D: the x-y plane;
3-D: from outside the contact face, read from ``contact.csv``, else from above a corner) and SaveScreenshot. It prints
the time values and the array names the reader found. A scene with contact also has ``contact.xdmf`` (Γ_C as a facet
mesh, solver/io/contact_series.py): it is drawn over the deformed body, warped alike, as a thick line (2-D) or its
faces (3-D), coloured by ``contact_pressure`` with a bar of its own, or by ``--field`` when that is one of its arrays
(the body is then light grey, see-through in 3-D); ``--no-contact`` leaves it out. Results written before
``contact.xdmf`` existed draw a contact field from ``contact.csv`` instead (CSV Reader, Table To Points, Threshold on
t, displaced as the body is): the nodes of Γ_C as dots over the body in grey.
This file imports only ``paraview``: no solver package, no dolfinx, no numpy.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import time as _time

# this file sits next to the solver's ``paraview.py``: drop its folder from the path, or ``import paraview`` finds that
_HERE = os.path.dirname(os.path.abspath(__file__))
sys.path[:] = [p for p in sys.path if os.path.abspath(p or os.curdir) != _HERE]

TITLES = {
    "von_mises_elastic": "von Mises norm of A eps(u)",
    "von_mises": "von Mises norm of sigma = A eps(u) + memory",
    "damage": "damage zeta",
    "displacement": "|displacement|",
    "stress": "|sigma| (Frobenius)",
    "elastic_stress": "|A eps(u)| (Frobenius)",
    "contact_pressure": "contact pressure p(u_nu - g) on the contact boundary",
    "penetration": "penetration u_nu - g on the contact boundary",
    "gap": "gap g on the contact boundary",
    "normal_displacement": "normal displacement u_nu on the contact boundary",
}
CONTACT_FILE = "contact.xdmf"
READERS = ("Xdmf3ReaderS", "Xdmf3ReaderT", "XDMFReader")
# a contact field's column in contact.csv (solver/io/layout.py PROFILE_COLUMNS)
CONTACT_COLUMNS = {"contact_pressure": "pressure", "gap": "gap", "penetration": "penetration", "u_normal": "u_normal"}
MISSING_PYTHON = ("error: ParaView's Python modules are not installed, which pvbatch needs "
                  "(Debian: apt-get install python3-paraview)")


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    """The command line (``sys.argv[1:]`` by default)."""
    p = argparse.ArgumentParser(prog="solver paraview", description="Render a results directory with ParaView (pvbatch).")
    p.add_argument("results", metavar="RESULTS_DIR", help="results directory holding solution.xdmf (or the .xdmf file itself)")
    p.add_argument("--field", default="von_mises_elastic", help="array to colour by (default: von_mises_elastic)")
    p.add_argument("--time", type=float, default=None, help="time to show (nearest written time; default: the last)")
    p.add_argument("--warp", type=float, default=None,
                   help="displacement scale factor (default: automatic, the largest displacement over the written "
                        "levels (21 of a longer series) drawn as 10%% of the body size, as solver plot does)")
    p.add_argument("--output", default=None, help="PNG to write (default: RESULTS_DIR/paraview_<field>.png)")
    p.add_argument("--size", type=int, nargs=2, default=(1200, 800), metavar=("W", "H"), help="image size in pixels")
    p.add_argument("--colormap", default=None, help="ParaView colour preset (default: Turbo; Inferno for damage)")
    p.add_argument("--range", type=float, nargs=2, default=None, metavar=("MIN", "MAX"),
                   help="colour range (default: the data range at the shown time)")
    p.add_argument("--reader", choices=("auto", *READERS), default="auto",
                   help="XDMF reader (default: the first of Xdmf3ReaderS, Xdmf3ReaderT, XDMFReader that reads the file)")
    p.add_argument("--edges", action="store_true", help="draw the mesh edges")
    p.add_argument("--no-contact", action="store_true",
                   help="do not draw the contact boundary (contact.xdmf, written by scenes with contact)")
    return p.parse_args(argv)


def fmt(t: float) -> str:
    """A time or factor as a short number (0.7000000000000001 -> 0.7)."""
    return f"{t:.12g}"


def nice_warp(size: float, umax: float) -> float:
    """10 % of the body size over the largest displacement, rounded down to 1, 2 or 5 x 10^m (1 if nothing moves)."""
    if umax <= 0 or size <= 0:
        return 1.0
    w = 0.1 * size / umax
    e = 10.0 ** math.floor(math.log10(w))
    return max(m for m in (1, 2, 5) if m * e <= w * (1 + 1e-12)) * e


def timesteps(reader) -> list[float]:
    """The reader's time values as a list (a one-step file may give a bare number)."""
    values = reader.TimestepValues
    if values is None:
        return []
    try:
        return [float(t) for t in values]
    except TypeError:
        return [float(values)]


def open_results(path: str, which: str):
    """The reader proxy for ``path``: the first of READERS (or ``which``) that gives time values and arrays."""
    import paraview.simple as pvs

    names = READERS if which == "auto" else (which,)
    errors = []
    for name in names:
        reader = None
        try:
            if name == "XDMFReader":
                reader = pvs.XDMFReader(FileNames=[path])
            else:
                reader = getattr(pvs, name)(FileName=[path])
            times = timesteps(reader)
            reader.UpdatePipeline(times[-1] if times else 0.0)
            if reader.GetDataInformation().GetNumberOfPoints() > 0 and (reader.PointData.keys() or reader.CellData.keys()):
                return name, reader
            errors.append(f"{name}: no points or arrays")
        except Exception as exc:  # a reader missing from this build, or one that cannot parse the file
            errors.append(f"{name}: {exc}")
        if reader is not None:
            pvs.Delete(reader)
    raise RuntimeError("no XDMF reader could read " + path + " (" + "; ".join(errors) + ")")


def arrays(data) -> str:
    """``name[components], ...`` of a proxy's PointData or CellData."""
    return ", ".join(f"{k}[{data[k].GetNumberOfComponents()}]" for k in data.keys()) or "(none)"


def max_abs_component(reader, t: float) -> float:
    """Largest |displacement component| at time ``t``: one time read, not a scan of the series (which costs
    a read per written level: 20 s for 1,001 levels)."""
    reader.UpdatePipeline(t)
    arr = reader.PointData["displacement"]
    umax = 0.0
    for c in range(arr.GetNumberOfComponents()):
        lo, hi = arr.GetRange(c)
        umax = max(umax, abs(lo), abs(hi))
    return umax


def fit_camera(view, bounds: tuple[float, ...], size: tuple[int, int]) -> None:
    """2-D parallel view of the x-y plane fitting ``bounds``, leaving room for the caption (top) and scalar bar (bottom)."""
    x0, x1, y0, y1, z0, z1 = bounds
    cx, cy, cz = (x0 + x1) / 2, (y0 + y1) / 2, (z0 + z1) / 2
    bw, bh = max(x1 - x0, 1e-12), max(y1 - y0, 1e-12)
    aspect = size[0] / size[1]
    top, bottom = 0.11, 0.15  # fractions of the image height kept free
    # parallel scale = half the visible height in world units
    scale = 1.04 * max(bh / (2 * (1 - top - bottom)), bw / (2 * aspect * 0.94))
    view.InteractionMode = "2D"
    view.CameraParallelProjection = 1
    # put the body centre in the middle of the free band, not of the image
    shift = (bottom - top) * scale
    dist = 10 * max(bw, bh)
    view.CameraFocalPoint = [cx, cy - shift, cz]
    view.CameraPosition = [cx, cy - shift, cz + dist]
    view.CameraViewUp = [0.0, 1.0, 0.0]
    view.CameraParallelScale = scale


def contact_face_centre(directory: str) -> tuple[float, float, float] | None:
    """The mean point of the contact nodes of the first level written to ``directory``/contact.csv (None: no such
    file, or no row): where the 3-D camera looks from."""
    import csv

    path = os.path.join(directory, "contact.csv")
    if not os.path.isfile(path):
        return None
    sums, n, first = [0.0, 0.0, 0.0], 0, None
    with open(path, newline="", encoding="utf-8") as fh:
        for row in csv.DictReader(fh):
            first = row["step"] if first is None else first
            if row["step"] != first:
                break
            for i, k in enumerate("xyz"):
                sums[i] += float(row[k])
            n += 1
    return tuple(v / n for v in sums) if n else None


def _unit(v):
    norm = math.sqrt(sum(c * c for c in v))
    return [c / norm for c in v] if norm > 0 else list(v)


def _cross(a, b):
    return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]


def view_direction(bounds: tuple[float, ...], face: tuple[float, float, float] | None) -> tuple[list, list]:
    """(unit vector from the body's centre to the camera, view-up) for a 3-D body: from outside the contact face
    (the direction from the centre to ``face``), turned 45 degrees away from its normal so that the faces beside it show
    too; without a contact face, from above the corner (1, -1, 1). View-up is +z unless the camera looks along z."""
    centre = [(bounds[2 * i] + bounds[2 * i + 1]) / 2 for i in range(3)]
    n = _unit([f - c for f, c in zip(face, centre)]) if face is not None else [0.0, 0.0, 0.0]
    if not any(n):
        d = _unit([1.0, -1.0, 1.0])
    else:
        k = min(range(3), key=lambda i: abs(n[i]))  # the axis least along n
        e = [1.0 if i == k else 0.0 for i in range(3)]
        a = _unit(_cross(n, e))
        b = _cross(n, a)
        d = _unit([n[i] + 0.8 * a[i] + 0.6 * b[i] for i in range(3)])
    up = [0.0, 0.0, 1.0] if abs(d[2]) < 0.9 else [0.0, 1.0, 0.0]
    return d, up


def fit_camera_3d(view, bounds: tuple[float, ...], face) -> None:
    """A perspective camera from :func:`view_direction`, fitting the body with room for the caption and bar."""
    d, up = view_direction(bounds, face)
    centre = [(bounds[2 * i] + bounds[2 * i + 1]) / 2 for i in range(3)]
    size = max(bounds[1] - bounds[0], bounds[3] - bounds[2], bounds[5] - bounds[4], 1e-12)
    view.InteractionMode = "3D"
    view.CameraParallelProjection = 0
    view.CameraFocalPoint = centre
    view.CameraPosition = [c + 4 * size * x for c, x in zip(centre, d)]
    view.CameraViewUp = up
    view.ResetCamera(False)
    # back off from the fitted distance (a vtkCamera Zoom is overwritten by the view's properties at render)
    fp, pos = list(view.CameraFocalPoint), list(view.CameraPosition)
    view.CameraPosition = [f + (q - f) / 0.72 for f, q in zip(fp, pos)]


def contact_points(pvs, directory: str, column: str, t: float, reader, has_u: bool, warp: float):
    """The contact nodes of the level written at ``t`` in ``directory``/contact.csv as points carrying its columns,
    displaced by ``warp`` times the body's displacement there (resampled from ``reader``); None if that level has no
    row. The GUI pipeline: CSV Reader, Table To Points, Mask Points (a vertex each), Threshold on t, Resample With
    Dataset, Append Attributes, Warp By Vector."""
    table = pvs.CSVReader(registrationName="contact.csv", FileName=[os.path.join(directory, "contact.csv")])
    points = pvs.TableToPoints(registrationName="ContactNodes", Input=table)
    points.XColumn, points.YColumn, points.ZColumn = "x", "y", "z"
    points.KeepAllDataArrays = 1
    # a vertex per point: Threshold keeps cells, and only cells are drawn
    verts = pvs.MaskPoints(registrationName="ContactVertices", Input=points)
    verts.OnRatio, verts.MaximumNumberofPoints, verts.RandomSampling = 1, 2_000_000_000, 0
    verts.GenerateVertices, verts.SingleVertexPerCell = 1, 1
    level = pvs.Threshold(registrationName="ContactLevel", Input=verts)
    level.Scalars = ["POINTS", "t"]
    tol = 1e-9 * max(1.0, abs(t))
    if hasattr(level, "LowerThreshold"):  # ParaView >= 5.10
        level.LowerThreshold, level.UpperThreshold = t - tol, t + tol
        level.ThresholdMethod = "Between"
    else:
        level.ThresholdRange = [t - tol, t + tol]
    level.UpdatePipeline(t)
    if level.GetDataInformation().GetNumberOfPoints() == 0:
        return None
    shown = level
    if has_u:
        # the displacement at the nodes (resampled from the body), appended to their columns (Resample With Dataset
        # passing the columns itself crashes ParaView 5.11 here)
        probe = pvs.ResampleWithDataset(registrationName="ContactDisplacement", SourceDataArrays=reader,
                                        DestinationMesh=level)
        both = pvs.AppendAttributes(registrationName="ContactNodesDisplaced", Input=[level, probe])
        shown = pvs.WarpByVector(registrationName="ContactWarp", Input=both)
        shown.Vectors = ["POINTS", "displacement"]
        shown.ScaleFactor = warp
    shown.UpdatePipeline(t)
    return shown


def _chosen_time(times: list, asked: float | None) -> float:
    """The written time to show: the last, or the one nearest to ``asked`` (with a note when not exact)."""
    if asked is None:
        return times[-1] if times else 0.0
    t = min(times, key=lambda s: abs(s - asked)) if times else 0.0
    if abs(t - asked) > 1e-9 * max(1.0, abs(asked)):
        print(f"note: --time {fmt(asked)} is not a written time; showing the nearest, t = {fmt(t)}")
    return t


WARP_LEVELS = 21  # the levels the automatic warp looks at: all of a short series, 21 evenly spaced of a longer one


def warp_levels(n: int) -> list[int]:
    """Indices of the written levels (of ``n``) whose displacement sets the automatic warp: all up to 21, else 21
    evenly spaced, first and last included (solver plot's plots.warp_levels: the same factor in both)."""
    if n <= WARP_LEVELS:
        return list(range(n))
    return sorted({round(i * (n - 1) / (WARP_LEVELS - 1)) for i in range(WARP_LEVELS)})


def _warp(args: argparse.Namespace, reader, times: list, t: float, body: float, has_u: bool) -> float:
    """The displacement's scale factor: the user's, or one that draws the largest displacement over the written
    levels (:func:`warp_levels`: 21 reads at most) as ~10% of the body, whatever the time shown: one factor for every
    picture of a run, ``solver plot``'s."""
    if not has_u:
        print("note: no 'displacement' array: drawing the undeformed mesh")
        return 0.0
    if args.warp is not None:
        return args.warp
    levels = [times[i] for i in warp_levels(len(times))] or [t]
    umax = max(max_abs_component(reader, s) for s in levels)
    reader.UpdatePipeline(t)
    warp = nice_warp(body, umax)
    print(f"warp: {fmt(warp)} (automatic: largest displacement {umax:.3g} over {len(levels)} written levels "
          f"drawn as ~10% of the body size {body:.3g})")
    return warp


def _view(pvs, size: tuple[int, int], t: float):
    """A white render view at time t."""
    try:
        pvs.LoadPalette("WhiteBackground")
    except Exception:  # older ParaView: set the colours by hand below
        pass
    view = pvs.CreateView("RenderView")
    view.ViewSize = list(size)
    view.ViewTime = t
    view.OrientationAxesVisibility = 0
    if hasattr(view, "UseColorPaletteForBackground"):
        view.UseColorPaletteForBackground = 0
    view.Background = [1.0, 1.0, 1.0]
    scene = pvs.GetAnimationScene()
    scene.UpdateAnimationUsingDataTimeSteps()
    scene.AnimationTime = t
    return view


def _pipeline(pvs, reader, t: float, has_u: bool, warp: float, solid: bool):
    """(the body warped by the displacement, the undeformed body's outline: its boundary in 2-D, the 30-degree
    feature edges of its surface in 3-D, whose surface has no boundary edges)."""
    shown = reader
    if has_u:
        shown = pvs.WarpByVector(registrationName="WarpByVector", Input=reader)
        shown.Vectors = ["POINTS", "displacement"]
        shown.ScaleFactor = warp
    shown.UpdatePipeline(t)
    outline = pvs.FeatureEdges(registrationName="Undeformed", Input=pvs.ExtractSurface(Input=reader))
    outline.BoundaryEdges = 0 if solid else 1
    outline.FeatureEdges = 1 if solid else 0
    outline.FeatureAngle = 30.0
    outline.NonManifoldEdges = 0
    outline.ManifoldEdges = 0
    outline.UpdatePipeline(t)
    return shown, outline


def _colour(pvs, args: argparse.Namespace, view, shown, assoc: str):
    """Show the body coloured by the field: (its colour map, the field's number of components)."""
    disp = pvs.Show(shown, view)
    disp.SetRepresentationType("Surface With Edges" if args.edges else "Surface")
    if args.edges:
        disp.EdgeColor = [0.25, 0.25, 0.25]
    disp.Ambient, disp.Diffuse = 1.0, 0.0  # unlit: the colours are exactly the colour map's
    pvs.ColorBy(disp, (assoc, args.field))
    lut = pvs.GetColorTransferFunction(args.field)
    ncomp = shown.GetDataInformation().GetArrayInformation(args.field, 0 if assoc == "POINTS" else 1).GetNumberOfComponents()
    if ncomp > 1:
        lut.VectorMode = "Magnitude"
    cmap = args.colormap or ("Inferno (matplotlib)" if args.field == "damage" else "Turbo")
    if not lut.ApplyPreset(cmap, True):
        print(f"note: no colour preset {cmap!r}; using Viridis")
        lut.ApplyPreset("Viridis (matplotlib)", True)
    if args.range:
        lut.RescaleTransferFunction(*args.range)
    else:
        disp.RescaleTransferFunctionToDataRange(False, True)
    pvs.GetOpacityTransferFunction(args.field).RescaleTransferFunction(lut.RGBPoints[0], lut.RGBPoints[-4])
    return disp, lut, ncomp


def _points(pvs, args: argparse.Namespace, view, nodes, column: str, H: int):
    """Show the contact nodes as dots coloured (unlit) by ``column``: (their display, the colour map)."""
    disp = pvs.Show(nodes, view)
    disp.SetRepresentationType("Points")
    disp.PointSize = max(6, H // 90)
    disp.RenderPointsAsSpheres = 0
    disp.Ambient, disp.Diffuse = 1.0, 0.0
    pvs.ColorBy(disp, ("POINTS", column))
    lut = pvs.GetColorTransferFunction(column)
    if not lut.ApplyPreset(args.colormap or "Turbo", True):
        lut.ApplyPreset("Viridis (matplotlib)", True)
    if args.range:
        lut.RescaleTransferFunction(*args.range)
    else:
        disp.RescaleTransferFunctionToDataRange(False, True)
    return disp, lut


def _scalar_bar(pvs, view, disp, lut, field: str, ncomp: int, H: int, side: bool = False) -> None:
    """The colour bar of ``disp``: horizontal below the picture, or (``side``) vertical on the right, for a second
    bar beside the main one (the contact boundary's)."""
    bar = pvs.GetScalarBar(lut, view)
    bar.Title = f"{field} (contact boundary)" if side else field
    bar.ComponentTitle = "(magnitude)" if ncomp > 1 else ""
    bar.Orientation = "Vertical" if side else "Horizontal"
    bar.WindowLocation = "Any Location"
    bar.Position = [0.9, 0.2] if side else [0.25, 0.03]
    bar.ScalarBarLength = 0.55 if side else 0.5
    bar.ScalarBarThickness = max(12, H // 50)
    bar.TitleFontSize = bar.LabelFontSize = max(12, H // 50)
    bar.TitleColor = bar.LabelColor = [0.0, 0.0, 0.0]
    bar.AutomaticLabelFormat = 0
    bar.LabelFormat = bar.RangeLabelFormat = "%-#.3g"
    bar.Visibility = 1
    disp.SetScalarBarVisibility(view, True)


def _captions(pvs, view, lines: tuple[str, str], H: int) -> None:
    """Two one-line texts: a multi-line, left-justified Text is laid out wrongly by ParaView 5.11 (lines shifted)."""
    fs = max(12, H // 45)
    for i, line in enumerate(lines):
        caption = pvs.Text(registrationName=f"Caption{i}")
        caption.Text = line
        cdisp = pvs.Show(caption, view)
        cdisp.WindowLocation = "Any Location"
        cdisp.Position = [0.01, 1.0 - (i + 1) * 1.6 * fs / H]
        cdisp.FontSize = fs
        cdisp.Color = [0.0, 0.0, 0.0]


def _contact_layer(pvs, args: argparse.Namespace, view, path: str, t: float, warp: float, field: str, H: int,
                   main_bar: bool):
    """Γ_C (contact.xdmf) warped as the body, coloured by ``field``: a thick line in 2-D, its faces in 3-D. With
    ``main_bar`` its bar is the picture's main one (bottom), else a second one on the right. Returns its display."""
    _, reader = open_results(path, "auto")
    shown = reader
    if "displacement" in reader.PointData.keys() and warp:
        shown = pvs.WarpByVector(registrationName="ContactWarp", Input=reader)
        shown.Vectors = ["POINTS", "displacement"]
        shown.ScaleFactor = warp
    shown.UpdatePipeline(t)
    disp = pvs.Show(shown, view)
    disp.SetRepresentationType("Surface")
    disp.Ambient, disp.Diffuse = 1.0, 0.0
    disp.LineWidth = max(5.0, H / 70)
    pvs.ColorBy(disp, ("POINTS", field))
    lut = pvs.GetColorTransferFunction(field)
    cmap = args.colormap if (main_bar and args.colormap) else "Turbo" if main_bar else "Inferno (matplotlib)"
    lut.ApplyPreset(cmap, True)
    if main_bar and args.range:
        lut.RescaleTransferFunction(*args.range)
    else:
        disp.RescaleTransferFunctionToDataRange(False, True)
    _scalar_bar(pvs, view, disp, lut, field, 1, H, side=not main_bar)
    return disp


def _lift_towards_camera(view, disp, size: float) -> None:
    """Move a display a little towards the camera (no change in a parallel projection's picture): Γ_C's faces
    coincide with the body's and would otherwise fight them in the depth buffer."""
    d = [p - f for p, f in zip(view.CameraPosition, view.CameraFocalPoint)]
    norm = math.sqrt(sum(c * c for c in d)) or 1.0
    disp.Position = [1e-3 * size * c / norm for c in d]  # the actor's translation


def render(args: argparse.Namespace) -> int:
    """Build the pipeline, print what the reader found, save the PNG; 0 on success, 2 on bad input."""
    start = _time.perf_counter()
    import paraview.simple as pvs

    given = args.results
    if os.path.isdir(given):
        given = os.path.join(given, "solution.xdmf")
    if not os.path.isfile(given):
        print(f"error: {args.results}: no solution.xdmf (is it a results directory?)", file=sys.stderr)
        return 2
    name, reader = open_results(os.path.abspath(given), args.reader)
    times = timesteps(reader)
    print(f"reader: {name}")
    shown_times = [fmt(t) for t in times] if len(times) <= 8 else [*map(fmt, times[:3]), "...", *map(fmt, times[-3:])]
    print(f"time values ({len(times)}): [{', '.join(shown_times)}]")
    print(f"point arrays: {arrays(reader.PointData)}")
    print(f"cell arrays: {arrays(reader.CellData)}")
    t = _chosen_time(times, args.time)
    directory = os.path.dirname(os.path.abspath(given))
    contact_path = os.path.join(directory, CONTACT_FILE)
    contact_names = []
    if not args.no_contact and os.path.isfile(contact_path):
        _, contact_reader = open_results(contact_path, "auto")
        contact_names = list(contact_reader.PointData.keys())
        print(f"contact boundary ({CONTACT_FILE}) point arrays: {arrays(contact_reader.PointData)}")
        pvs.Delete(contact_reader)
    # a field of Γ_C's own dataset is drawn there (rather than as the body's vertex field, zero off Γ_C)
    on_contact = args.field in contact_names and args.field != "displacement"
    from_csv = None  # older results without contact.xdmf: the contact.csv column drawn on the contact nodes
    if on_contact:
        assoc = "POINTS"
    elif args.field in reader.CellData.keys():
        assoc = "CELLS"
    elif args.field in reader.PointData.keys():
        assoc = "POINTS"
    elif args.field in CONTACT_COLUMNS and os.path.isfile(os.path.join(directory, "contact.csv")):
        assoc, from_csv = "POINTS", CONTACT_COLUMNS[args.field]
        print(f"note: {args.field} is not in solution.xdmf (output.fields): drawn from contact.csv's "
              f"'{from_csv}' column at the contact nodes")
    else:
        names = list(reader.PointData.keys()) + list(reader.CellData.keys())
        names += [f"{n} ({CONTACT_FILE})" for n in contact_names if n != "displacement"]
        print(f"error: --field {args.field}: not in the file (it has {', '.join(names)})", file=sys.stderr)
        return 2
    has_u = "displacement" in reader.PointData.keys()
    reader.UpdatePipeline(t)
    b = reader.GetDataInformation().GetBounds()
    solid = b[5] - b[4] > 1e-12 * max(b[1] - b[0], b[3] - b[2], 1.0)
    warp = _warp(args, reader, times, t, max(b[1] - b[0], b[3] - b[2], b[5] - b[4]), has_u)
    nodes = None if from_csv is None else contact_points(pvs, directory, from_csv, t, reader, has_u, warp)
    if from_csv is not None and nodes is None:  # before the view is made: a view left at exit is an X error
        print(f"error: --field {args.field}: contact.csv has no row at t = {fmt(t)}", file=sys.stderr)
        return 2
    W, H = args.size
    view = _view(pvs, (W, H), t)
    shown, outline = _pipeline(pvs, reader, t, has_u, warp, solid)
    lut, ncomp = None, 1
    if on_contact:  # the body in light grey under Γ_C coloured by the field
        disp = pvs.Show(shown, view)
        disp.SetRepresentationType("Surface With Edges" if args.edges else "Surface")
        disp.ColorArrayName = ["POINTS", ""]
        disp.AmbientColor = disp.DiffuseColor = [0.86, 0.86, 0.86]
        disp.Ambient, disp.Diffuse = 1.0, 0.0
        if solid:  # 3-D: the body see-through, so that Γ_C shows from any side
            disp.Opacity = 0.3
        kind = f"point data, {CONTACT_FILE}"
    elif from_csv is None:
        disp, lut, ncomp = _colour(pvs, args, view, shown, assoc)
        kind = "cell data" if assoc == "CELLS" else "point data"
    else:
        body = pvs.Show(shown, view)
        body.ColorArrayName = ["POINTS", ""]
        body.AmbientColor = body.DiffuseColor = [0.82, 0.82, 0.82]
        disp, lut = _points(pvs, args, view, nodes, from_csv, H)
        kind = "contact.csv, at the contact nodes"
    contact = None
    if contact_names:
        contact = _contact_layer(pvs, args, view, contact_path, t, warp,
                                 args.field if on_contact else "contact_pressure", H, main_bar=on_contact)
    odisp = pvs.Show(outline, view)
    odisp.ColorArrayName = ["POINTS", ""]  # a solid colour (ColorBy(rep, None) fails on a 3-D outline: association NONE)
    odisp.AmbientColor = odisp.DiffuseColor = [0.45, 0.45, 0.45]
    odisp.LineWidth = 2.0
    if not on_contact:
        _scalar_bar(pvs, view, disp, lut, args.field, ncomp, H)
    line2 = f"t = {fmt(t)}, displacement x {fmt(warp)}  (grey: undeformed {'edges' if solid else 'boundary'})"
    if contact is not None and not on_contact:
        line2 += "; contact boundary: contact_pressure"
    _captions(pvs, view, (f"{TITLES.get(args.field, args.field)}  ({args.field}, {kind})", line2), H)
    wb = shown.GetDataInformation().GetBounds()
    bounds = tuple(f(a, c) for a, c, f in zip(wb, b, (min, max, min, max, min, max)))
    if solid:
        fit_camera_3d(view, bounds, contact_face_centre(directory))
    else:
        fit_camera(view, bounds, (W, H))
    if contact is not None:
        _lift_towards_camera(view, contact, max(b[1] - b[0], b[3] - b[2], b[5] - b[4]))
    out = args.output or os.path.join(os.path.dirname(given), f"paraview_{args.field}.png")
    os.makedirs(os.path.dirname(os.path.abspath(out)), exist_ok=True)
    before = os.stat(out).st_mtime_ns if os.path.exists(out) else None
    pvs.Render(view)
    pvs.SaveScreenshot(out, view, ImageResolution=[W, H], TransparentBackground=0)
    if not os.path.exists(out) or os.stat(out).st_mtime_ns == before:  # VTK only logs "Unable to open file"
        print(f"error: {out}: ParaView could not write it", file=sys.stderr)
        pvs.Delete(view)
        return 2
    # delete the view before Python exits: left to the interpreter's teardown, Debian's X build fails with
    # "GLXBadContext" and exit code 1 although the PNG was written
    pvs.Delete(view)
    del view
    print(f"wrote {out} ({W}x{H}, field {args.field} ({kind}), t = {fmt(t)}, warp {fmt(warp)}) "
          f"in {_time.perf_counter() - start:.1f} s")
    return 0


def main(argv: list[str] | None = None) -> int:
    """Entry point under pvbatch/pvpython; ``--check`` only tests that ParaView's Python modules import."""
    argv = list(sys.argv[1:] if argv is None else argv)
    try:
        import paraview.simple  # noqa: F401
    except ImportError:  # Debian's paraview without python3-paraview (a Recommends, skipped by --no-install-recommends)
        print(MISSING_PYTHON, file=sys.stderr)
        return 2
    if argv == ["--check"]:
        print("ok")
        return 0
    try:
        return render(parse_args(argv))
    except RuntimeError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())
