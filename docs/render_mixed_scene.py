"""Render the last snapshot of a mixed ballast stage in ParaView: the clumps of a sphere bed
(sphere glyphs of their diameter, one colour per body) under the polyhedral plate or sleeper,
inside the translucent box; prints what ParaView read (point and cell counts, bounds).

Run with ParaView's batch interpreter (Debian: ``apt install paraview python3-paraview xvfb``)::

    xvfb-run -a pvbatch docs/render_mixed_scene.py RUN_DIR STAGE OUT.png

e.g. ``runs/ballast_box_clumps vibrate docs/ballast_figures/clump_bed_plate.png`` after
``demcli run cases/smoke/ballast_box_clumps.yaml --out runs/ballast_box_clumps``.
"""

import sys

from paraview.simple import ColorBy, CreateView, GetAnimationScene, Glyph, PVDReader, Render, SaveScreenshot, Show

WIDTH, HEIGHT = 1000, 700


def main(run, stage, out):
    folder = f"{run}/{stage}"
    balls = PVDReader(FileName=f"{folder}/spheres.pvd")
    poly = PVDReader(FileName=f"{folder}/polyhedra.pvd")
    walls = PVDReader(FileName=f"{folder}/walls.pvd")
    scene = GetAnimationScene()
    scene.UpdateAnimationUsingDataTimeSteps()
    scene.AnimationTime = balls.TimestepValues[-1]
    glyphs = Glyph(Input=balls, GlyphType="Sphere")
    glyphs.ScaleArray = ["POINTS", "diameter"]
    glyphs.ScaleFactor = 1.0
    glyphs.GlyphMode = "All Points"
    view = CreateView("RenderView")
    view.ViewSize = [WIDTH, HEIGHT]
    view.Background = [1, 1, 1]
    if hasattr(view, "UseColorPaletteForBackground"):
        view.UseColorPaletteForBackground = 0
    shown = Show(glyphs, view)
    ColorBy(shown, ("POINTS", "body_id"))
    shown.RescaleTransferFunctionToDataRange(True)
    actor = Show(poly, view)
    actor.DiffuseColor = actor.AmbientColor = [0.6, 0.6, 0.65]
    Show(walls, view).Opacity = 0.15
    view.CameraPosition = [0.57, -0.525, 0.45]
    view.CameraFocalPoint = [0.12, 0.075, 0.15]
    view.CameraViewUp = [0, 0, 1]
    Render(view)
    SaveScreenshot(out, view, ImageResolution=[WIDTH, HEIGHT])
    for name, src in (("spheres", balls), ("polyhedra", poly)):
        src.UpdatePipeline(balls.TimestepValues[-1])
        info = src.GetDataInformation()
        print(f"{name}: {info.GetNumberOfPoints()} points, {info.GetNumberOfCells()} cells, bounds "
              + " ".join(f"{b:.4f}" for b in info.GetBounds()))


if __name__ == "__main__":
    main(*sys.argv[1:4])
