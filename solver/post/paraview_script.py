"""Render a results directory with ParaView: run me with ``pvbatch`` (or ``pvpython``), not with the solver's Python.

    pvbatch --force-offscreen-rendering solver/post/paraview_script.py RESULTS_DIR [--field von_mises_elastic] [--time T]
        [--warp W] [--output PNG] [--size 1200 800]

(``python -m solver paraview RESULTS_DIR ...`` does this for you, under ``xvfb-run`` when there is no display.)

The pipeline is the one a user builds in the GUI: open ``solution.xdmf`` (reader ``Xdmf3ReaderS``), go to a time,
Warp By Vector with ``displacement``, colour by a cell (or point) field, plus a scalar bar, a caption and the undeformed
boundary in grey; then a 2-D camera fitting the body and SaveScreenshot. It prints the time values and the array names
the reader found. This file imports only ``paraview``: no solver package, no dolfinx, no numpy.
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
}
READERS = ("Xdmf3ReaderS", "Xdmf3ReaderT", "XDMFReader")
MISSING_PYTHON = ("error: ParaView's Python modules are not installed, which pvbatch needs "
                  "(Debian: apt-get install python3-paraview)")


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    """The command line (``sys.argv[1:]`` by default)."""
    p = argparse.ArgumentParser(prog="solver paraview", description="Render a results directory with ParaView (pvbatch).")
    p.add_argument("results", metavar="RESULTS_DIR", help="results directory holding solution.xdmf (or the .xdmf file itself)")
    p.add_argument("--field", default="von_mises_elastic", help="array to colour by (default: von_mises_elastic)")
    p.add_argument("--time", type=float, default=None, help="time to show (nearest written time; default: the last)")
    p.add_argument("--warp", type=float, default=None,
                   help="displacement scale factor (default: automatic, the largest displacement at the shown time "
                        "drawn as 10%% of the body size)")
    p.add_argument("--output", default=None, help="PNG to write (default: RESULTS_DIR/paraview_<field>.png)")
    p.add_argument("--size", type=int, nargs=2, default=(1200, 800), metavar=("W", "H"), help="image size in pixels")
    p.add_argument("--colormap", default=None, help="ParaView colour preset (default: Turbo; Inferno for damage)")
    p.add_argument("--range", type=float, nargs=2, default=None, metavar=("MIN", "MAX"),
                   help="colour range (default: the data range at the shown time)")
    p.add_argument("--reader", choices=("auto", *READERS), default="auto",
                   help="XDMF reader (default: the first of Xdmf3ReaderS, Xdmf3ReaderT, XDMFReader that reads the file)")
    p.add_argument("--edges", action="store_true", help="draw the mesh edges")
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


def _chosen_time(times: list, asked: float | None) -> float:
    """The written time to show: the last, or the one nearest to ``asked`` (with a note when not exact)."""
    if asked is None:
        return times[-1] if times else 0.0
    t = min(times, key=lambda s: abs(s - asked)) if times else 0.0
    if abs(t - asked) > 1e-9 * max(1.0, abs(asked)):
        print(f"note: --time {fmt(asked)} is not a written time; showing the nearest, t = {fmt(t)}")
    return t


def _warp(args: argparse.Namespace, reader, t: float, body: float, has_u: bool) -> float:
    """The displacement's scale factor: the user's, or one that draws the largest displacement as ~10% of the body."""
    if not has_u:
        print("note: no 'displacement' array: drawing the undeformed mesh")
        return 0.0
    if args.warp is not None:
        return args.warp
    umax = max_abs_component(reader, t)
    warp = nice_warp(body, umax)
    print(f"warp: {fmt(warp)} (automatic: largest displacement {umax:.3g} at t = {fmt(t)} "
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


def _pipeline(pvs, reader, t: float, has_u: bool, warp: float):
    """(the body warped by the displacement, the undeformed boundary's outline)."""
    shown = reader
    if has_u:
        shown = pvs.WarpByVector(registrationName="WarpByVector", Input=reader)
        shown.Vectors = ["POINTS", "displacement"]
        shown.ScaleFactor = warp
    shown.UpdatePipeline(t)
    outline = pvs.FeatureEdges(registrationName="Undeformed", Input=pvs.ExtractSurface(Input=reader))
    outline.BoundaryEdges = 1
    outline.FeatureEdges = 0
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


def _scalar_bar(pvs, view, disp, lut, field: str, ncomp: int, H: int) -> None:
    bar = pvs.GetScalarBar(lut, view)
    bar.Title = field
    bar.ComponentTitle = "(magnitude)" if ncomp > 1 else ""
    bar.Orientation = "Horizontal"
    bar.WindowLocation = "Any Location"
    bar.Position = [0.25, 0.03]
    bar.ScalarBarLength = 0.5
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
    if args.field in reader.CellData.keys():
        assoc = "CELLS"
    elif args.field in reader.PointData.keys():
        assoc = "POINTS"
    else:
        names = list(reader.PointData.keys()) + list(reader.CellData.keys())
        print(f"error: --field {args.field}: not in the file (it has {', '.join(names)})", file=sys.stderr)
        return 2
    has_u = "displacement" in reader.PointData.keys()
    reader.UpdatePipeline(t)
    b = reader.GetDataInformation().GetBounds()
    warp = _warp(args, reader, t, max(b[1] - b[0], b[3] - b[2], b[5] - b[4]), has_u)
    W, H = args.size
    view = _view(pvs, (W, H), t)
    shown, outline = _pipeline(pvs, reader, t, has_u, warp)
    disp, lut, ncomp = _colour(pvs, args, view, shown, assoc)
    odisp = pvs.Show(outline, view)
    odisp.ColorArrayName = ["POINTS", ""]  # a solid colour (ColorBy(rep, None) fails on a 3-D outline: association NONE)
    odisp.AmbientColor = odisp.DiffuseColor = [0.45, 0.45, 0.45]
    odisp.LineWidth = 2.0
    _scalar_bar(pvs, view, disp, lut, args.field, ncomp, H)
    kind = "cell data" if assoc == "CELLS" else "point data"
    _captions(pvs, view, (f"{TITLES.get(args.field, args.field)}  ({args.field}, {kind})",
                          f"t = {fmt(t)}, displacement x {fmt(warp)}  (grey: undeformed boundary)"), H)
    wb = shown.GetDataInformation().GetBounds()
    fit_camera(view, tuple(f(a, c) for a, c, f in zip(wb, b, (min, max, min, max, min, max))), (W, H))
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
