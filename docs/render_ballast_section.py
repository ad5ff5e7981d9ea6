"""Render the last snapshot of a ballast stage in ParaView: a cut through the box's mid-plane
(whole stones kept), coloured by sieve size (the sleeper and plate have 0).

Run with ParaView's batch interpreter (Debian: ``apt install paraview xvfb``)::

    xvfb-run -a pvbatch docs/render_ballast_section.py RUN_DIR STAGE OUT.png "TITLE"

e.g. ``runs/ballast_wide sleeper docs/ballast_figures_full/wide_sleeper_section.png "wide"``.
The box is the seeds' 0.6 x 0.3 m section; the camera looks along +y at the cut y = 0.15 m.
"""

import sys

from paraview.simple import (Clip, ColorBy, CreateView, GetAnimationScene,
                             GetColorTransferFunction, GetScalarBar, PVDReader, Render, SaveScreenshot, Show,
                             Text)

WIDTH, HEIGHT = 1400, 800
MAX_SIEVE = 0.063  # m: the colour scale of all three gradations


def main(run, stage, out, title):
    poly = PVDReader(FileName=f"{run}/{stage}/polyhedra.pvd")
    scene = GetAnimationScene()
    scene.UpdateAnimationUsingDataTimeSteps()
    scene.AnimationTime = poly.TimestepValues[-1]
    view = CreateView("RenderView")
    view.ViewSize = [WIDTH, HEIGHT]
    view.Background = [1, 1, 1]
    if hasattr(view, "UseColorPaletteForBackground"):
        view.UseColorPaletteForBackground = 0
    view.OrientationAxesVisibility = 0
    clip = Clip(Input=poly)
    clip.ClipType = "Plane"
    clip.ClipType.Origin = [0.3, 0.15, 0.2]
    clip.ClipType.Normal = [0, -1, 0]
    clip.Crinkleclip = 1
    shown = Show(clip, view)
    ColorBy(shown, ("CELLS", "sieve_size"))
    lut = GetColorTransferFunction("sieve_size")
    lut.ApplyPreset("Viridis (matplotlib)", True)
    lut.RescaleTransferFunction(0.0, MAX_SIEVE)
    bar = GetScalarBar(lut, view)
    bar.Title = "sieve size [m] (sleeper: 0)"
    bar.ComponentTitle = ""
    bar.TitleColor = bar.LabelColor = [0, 0, 0]
    shown.SetScalarBarVisibility(view, True)
    label = Show(Text(Text=title), view)
    label.Color = [0, 0, 0]
    label.FontSize = 14
    label.WindowLocation = "Upper Left Corner"
    cam = view.GetActiveCamera()
    cam.SetFocalPoint(0.3, 0.15, 0.22)
    cam.SetPosition(0.3, -1.35, 0.5)
    cam.SetViewUp(0, 0, 1)
    view.ResetCamera()
    cam.Zoom(1.35)
    Render(view)
    SaveScreenshot(out, view, ImageResolution=[WIDTH, HEIGHT])
    print(f"{run}/{stage} at t = {poly.TimestepValues[-1]:.4g} s -> {out}")


if __name__ == "__main__":
    main(*sys.argv[1:5])
