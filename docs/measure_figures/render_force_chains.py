"""Render a stage's force network in ParaView: the contacts of ``force_chains.pvd`` as tubes whose
radius and colour follow their normal force (only those pushing, F_n > 0), over the translucent
particles (``polyhedra.pvd``, or sphere glyphs of ``spheres.pvd``); prints what ParaView read.

Run with ParaView's batch interpreter (Debian: ``apt install paraview python3-paraview xvfb``)::

    xvfb-run -a pvbatch docs/measure_figures/render_force_chains.py STAGE_DIR SNAPSHOT OUT.png

e.g. ``runs/box/sleeper 5 docs/measure_figures/ballast_box_force_chains.png`` after the run of
docs/measure.md (snapshot 5: the peak load of the sleeper's cycle).
"""

import os
import sys

from paraview.simple import (ColorBy, CreateView, ExtractSurface, GetAnimationScene, GetColorTransferFunction,
                             GetScalarBar, Glyph, PVDReader, Render, SaveScreenshot, Show, Threshold, Tube)

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


def main(folder, snapshot, out):
    chains = PVDReader(FileName=f"{folder}/force_chains.pvd")
    scene = GetAnimationScene()
    scene.UpdateAnimationUsingDataTimeSteps()
    time = chains.TimestepValues[int(snapshot)]
    scene.AnimationTime = time
    view = CreateView("RenderView")
    view.ViewSize = [WIDTH, HEIGHT]
    view.Background = [1, 1, 1]
    if hasattr(view, "UseColorPaletteForBackground"):
        view.UseColorPaletteForBackground = 0
    view.OrientationAxesVisibility = 0
    particles = _particles(folder, view)
    pushing = Threshold(Input=chains, Scalars=["CELLS", "normal_force"])
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
    shown = Show(tubes, view)
    ColorBy(shown, ("CELLS", "normal_force"))
    shown.RescaleTransferFunctionToDataRange(True)
    lut = GetColorTransferFunction("normal_force")
    lut.ApplyPreset("Inferno (matplotlib)", True)
    lut.InvertTransferFunction()
    shown.SetScalarBarVisibility(view, True)
    bar = GetScalarBar(lut, view)
    bar.Title, bar.ComponentTitle = "Normal force (N)", ""
    bar.TitleColor = bar.LabelColor = [0, 0, 0]
    bar.TitleFontSize, bar.LabelFontSize = 18, 16
    Render(view)  # the first render fits the camera to the scene; then set it
    view.CameraPosition = [0.26, -0.46, 0.27]
    view.CameraFocalPoint = [0.12, 0.075, 0.12]
    view.CameraViewUp = [0, 0, 1]
    Render(view)
    SaveScreenshot(out, view, ImageResolution=[WIDTH, HEIGHT])
    for name, src in (("force_chains", chains), ("particles", particles), ("tubes (F_n > 0)", tubes)):
        src.UpdatePipeline(time)
        info = src.GetDataInformation()
        print(f"{name} at t = {time:.4g} s: {info.GetNumberOfPoints()} points, {info.GetNumberOfCells()} cells, "
              "bounds " + " ".join(f"{b:.4f}" for b in info.GetBounds()))


if __name__ == "__main__":
    main(*sys.argv[1:4])
