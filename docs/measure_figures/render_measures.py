"""Render a stage's measures in ParaView (docs/measure.md); prints what ParaView read.

* ``chains``: the contacts of ``force_chains.pvd`` as tubes whose radius and colour follow their
  normal force (only those pushing, F_n > 0), over the translucent particles (``polyhedra.pvd``,
  or sphere glyphs of ``spheres.pvd``);
* ``mesh``: the polyhedra (``polyhedra.pvd``, if any) on the stage's
  walls (``walls.pvd``: STL/OBJ meshes and the other walls as surfaces), seen from above at an angle;
* ``fields``: the coarse-grained pressure of ``fields.pvd`` on the vertical slice through the
  grid's middle (normal y), with the particles cut there as outlines.

Run with ParaView's batch interpreter (Debian: ``apt install paraview python3-paraview xvfb``)::

    xvfb-run -a pvbatch docs/measure_figures/render_measures.py chains|fields|mesh STAGE_DIR SNAPSHOT OUT.png

e.g. ``chains runs/box/sleeper 5 docs/measure_figures/ballast_box_force_chains.png`` after the
run of docs/measure.md (snapshot 5: just after the peak load of the sleeper's cycle).
"""

import os
import sys

from paraview.simple import (Calculator, ColorBy, CreateView, ExtractSurface, GetAnimationScene,
                             GetColorTransferFunction, GetScalarBar, Glyph, PVDReader, Render, SaveScreenshot, Show,
                             Slice, Threshold, Tube)

WIDTH, HEIGHT = 1200, 800


def _particles(folder, view):
    """Show the particles translucent grey; returns their reader."""
    if os.path.exists(f"{folder}/polyhedra.pvd"):
        src = PVDReader(FileName=f"{folder}/polyhedra.pvd")
        shown = Show(src, view)
    else:
        src = PVDReader(FileName=f"{folder}/spheres.pvd")
        glyphs = Glyph(Input=src, GlyphType="Sphere")
        glyphs.ScaleArray = ["POINTS", "diameter"]
        glyphs.ScaleFactor = 1.0
        glyphs.GlyphMode = "All Points"
        shown = Show(glyphs, view)
    shown.DiffuseColor = shown.AmbientColor = [0.75, 0.75, 0.78]
    shown.Opacity = 0.25
    return src


def _view(reader, snapshot):
    """A white render view at the reader's snapshot; returns (view, time)."""
    scene = GetAnimationScene()
    scene.UpdateAnimationUsingDataTimeSteps()
    time = reader.TimestepValues[int(snapshot)]
    scene.AnimationTime = time
    view = CreateView("RenderView")
    view.ViewSize = [WIDTH, HEIGHT]
    view.Background = [1, 1, 1]
    if hasattr(view, "UseColorPaletteForBackground"):
        view.UseColorPaletteForBackground = 0
    view.OrientationAxesVisibility = 0
    return view, time


def _colour_bar(shown, view, array, title, preset, invert=False):
    """Colour ``shown`` by the point or cell ``array`` (association, name) with a titled bar."""
    ColorBy(shown, array)
    shown.RescaleTransferFunctionToDataRange(True)
    lut = GetColorTransferFunction(array[1])
    lut.ApplyPreset(preset, True)
    if invert:
        lut.InvertTransferFunction()
    shown.SetScalarBarVisibility(view, True)
    bar = GetScalarBar(lut, view)
    bar.Title, bar.ComponentTitle = title, ""
    bar.TitleColor = bar.LabelColor = [0, 0, 0]
    bar.TitleFontSize, bar.LabelFontSize = 18, 16


def _camera(view, position, focus):
    Render(view)  # the first render fits the camera to the scene; then set it
    view.CameraPosition = position
    view.CameraFocalPoint = focus
    view.CameraViewUp = [0, 0, 1]
    Render(view)


def _report(time, sources):
    for name, src in sources:
        src.UpdatePipeline(time)
        info = src.GetDataInformation()
        print(f"{name} at t = {time:.4g} s: {info.GetNumberOfPoints()} points, {info.GetNumberOfCells()} cells, "
              "bounds " + " ".join(f"{b:.4f}" for b in info.GetBounds()))


def chains(folder, snapshot, out):
    reader = PVDReader(FileName=f"{folder}/force_chains.pvd")
    view, time = _view(reader, snapshot)
    particles = _particles(folder, view)
    pushing = Threshold(Input=reader, Scalars=["CELLS", "normal_force"])
    if hasattr(pushing, "LowerThreshold"):
        pushing.LowerThreshold, pushing.UpperThreshold = 1e-9, 1e30
    else:
        pushing.ThresholdRange = [1e-9, 1e30]
    tubes = Tube(Input=ExtractSurface(Input=pushing))
    tubes.Scalars = ["POINTS", "normal_force"]
    tubes.VaryRadius = "By Scalar"
    tubes.Radius = 0.0008
    tubes.RadiusFactor = 8.0
    tubes.NumberofSides = 16
    _colour_bar(Show(tubes, view), view, ("CELLS", "normal_force"), "Normal force (N)", "Inferno (matplotlib)",
                invert=True)
    _camera(view, [0.26, -0.46, 0.27], [0.12, 0.075, 0.12])
    SaveScreenshot(out, view, ImageResolution=[WIDTH, HEIGHT])
    _report(time, (("force_chains", reader), ("particles", particles), ("tubes (F_n > 0)", tubes)))


def fields(folder, snapshot, out):
    reader = PVDReader(FileName=f"{folder}/fields.pvd")
    view, time = _view(reader, snapshot)
    kpa = Calculator(Input=reader, ResultArrayName="pressure_kPa", Function="pressure/1000")
    cut = Slice(Input=kpa)
    cut.SliceType = "Plane"
    reader.UpdatePipeline(time)
    bounds = reader.GetDataInformation().GetBounds()
    middle = [(bounds[0] + bounds[1]) / 2, (bounds[2] + bounds[3]) / 2, (bounds[4] + bounds[5]) / 2]
    cut.SliceType.Origin = middle
    cut.SliceType.Normal = [0, 1, 0]
    _colour_bar(Show(cut, view), view, ("POINTS", "pressure_kPa"), "Pressure (kPa)", "Viridis (matplotlib)")
    if os.path.exists(f"{folder}/polyhedra.pvd"):
        outline = Slice(Input=PVDReader(FileName=f"{folder}/polyhedra.pvd"))
        outline.SliceType = "Plane"
        outline.SliceType.Origin = [middle[0], middle[1] - 1e-3, middle[2]]  # just in front of the field
        outline.SliceType.Normal = [0, 1, 0]
        lines = Show(outline, view)
        lines.DiffuseColor = lines.AmbientColor = [1, 1, 1]
        lines.LineWidth = 2.0
    _camera(view, [middle[0], middle[1] - 0.6, middle[2]], middle)
    SaveScreenshot(out, view, ImageResolution=[WIDTH, HEIGHT])
    _report(time, (("fields", reader), ("slice", cut)))


def mesh(folder, snapshot, out):
    walls = PVDReader(FileName=f"{folder}/walls.pvd")
    view, time = _view(walls, snapshot)
    shown = Show(walls, view)
    shown.DiffuseColor = shown.AmbientColor = [0.55, 0.62, 0.75]
    shown.Representation = "Surface With Edges"
    bodies = PVDReader(FileName=f"{folder}/polyhedra.pvd") if os.path.exists(f"{folder}/polyhedra.pvd") else None
    if bodies is not None:
        b = Show(bodies, view)
        b.DiffuseColor = b.AmbientColor = [0.80, 0.55, 0.35]
    walls.UpdatePipeline(time)
    lo = walls.GetDataInformation().GetBounds()
    middle = [(lo[0] + lo[1]) / 2, (lo[2] + lo[3]) / 2, (lo[4] + lo[5]) / 2]
    span = max(lo[1] - lo[0], lo[3] - lo[2])
    _camera(view, [middle[0] + 0.6 * span, middle[1] - 1.2 * span, middle[2] + 0.9 * span], middle)
    SaveScreenshot(out, view, ImageResolution=[WIDTH, HEIGHT])
    _report(time, (("walls", walls),) + ((("bodies", bodies),) if bodies is not None else ()))


if __name__ == "__main__":
    {"chains": chains, "fields": fields, "mesh": mesh}[sys.argv[1]](*sys.argv[2:5])
