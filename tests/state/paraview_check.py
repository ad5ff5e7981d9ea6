"""Check that ParaView reads demcli's VTU/PVD output (a script, not a pytest test).

Two steps, because pvbatch runs its own Python without demcli's virtual environment:

    .venv/bin/python tests/state/paraview_check.py make /tmp/pvcheck
    xvfb-run -a pvbatch tests/state/paraview_check.py render /tmp/pvcheck /tmp/pvcheck/spheres.png

``make`` writes a small pile of clumps in a box (speed grows with height, so the
colours run from blue at the bottom to red at the top) as two snapshots with
``spheres.pvd`` and ``walls.pvd``, plus ``expected.json`` (sphere count, the glyph
bounds and the speed range). ``render`` opens the .pvd series, applies a Glyph
filter with sphere glyphs scaled by ``diameter``, colours by velocity magnitude,
draws the walls translucent, saves a PNG, and compares what ParaView read with
``expected.json``; it exits non-zero on a mismatch.
"""

import json
import os
import sys
from pathlib import Path


def make(folder):
    import numpy as np

    from demcli.state.fields import example_state
    from demcli.state.vtu import Snapshots

    folder = Path(folder)
    state = example_state(n_bodies=125, spheres_per_body=3, seed=1)
    g = np.stack(np.meshgrid(*[np.arange(5)] * 3, indexing="ij"), axis=-1).reshape(-1, 3)
    state["bodies/x"] = 0.012 + 0.019 * g * [1.0, 1.0, 1.3]
    state["bodies/omega"] = np.zeros((125, 3))
    snaps = Snapshots(folder)
    for k in range(2):
        z = state["bodies/x"][:, 2]
        state["bodies/v"] = np.stack([0 * z, 0 * z, -10.0 * z], axis=1)
        state.meta["time"] = 0.01 * k
        snaps.write(state)
        state["bodies/x"] = state["bodies/x"] - [0, 0, 0.002]
    centres, r = state.sphere_centres() + [0, 0, 0.002], state["spheres/radius"]
    speed = np.linalg.norm(state.sphere_velocities(), axis=1)
    expected = {"n_spheres": int(len(r)),
                "bounds": [float(v) for k in range(3) for v in
                           ((centres[:, k] - r).min(), (centres[:, k] + r).max())],
                "speed": [float(speed.min()), float(speed.max())],
                "times": [0.0, 0.01]}
    (folder / "expected.json").write_text(json.dumps(expected, indent=1))
    print(f"wrote {folder}/spheres.pvd, walls.pvd and expected.json")


def render(folder, png):
    from paraview import servermanager as sm
    from paraview import simple as pv

    folder = Path(folder)
    expected = json.loads((folder / "expected.json").read_text())
    problems = []

    reader = pv.PVDReader(FileName=str(folder / "spheres.pvd"))
    reader.UpdatePipelineInformation()
    times = list(reader.TimestepValues)
    if [round(t, 9) for t in times] != expected["times"]:
        problems.append(f"time steps {times} != {expected['times']}")
    t_last = times[-1]
    reader.UpdatePipeline(t_last)
    data = sm.Fetch(reader)
    n_points = data.GetNumberOfPoints()
    arrays = [data.GetPointData().GetArrayName(i) for i in range(data.GetPointData().GetNumberOfArrays())]
    print(f"ParaView read {n_points} points with point arrays {arrays}")
    if n_points != expected["n_spheres"]:
        problems.append(f"{n_points} points, expected {expected['n_spheres']}")
    for name in ("radius", "diameter", "velocity", "omega", "body_id", "material"):
        if name not in arrays:
            problems.append(f"point array {name!r} missing")
    vel = data.GetPointData().GetArray("velocity")
    speed_range = vel.GetRange(-1)
    print(f"velocity magnitude range {speed_range}, expected {expected['speed']}")
    if abs(speed_range[0] - expected["speed"][0]) > 1e-9 or abs(speed_range[1] - expected["speed"][1]) > 1e-9:
        problems.append(f"speed range {speed_range} != {expected['speed']}")

    view = pv.CreateView("RenderView")
    view.ViewSize = [900, 700]
    view.ViewTime = t_last
    view.OrientationAxesVisibility = 1
    view.Background = [1, 1, 1]
    try:
        view.UseColorPaletteForBackground = 0
    except AttributeError:
        pass

    glyph = pv.Glyph(Input=reader, GlyphType="Sphere")
    glyph.ScaleArray = ["POINTS", "diameter"]
    glyph.ScaleFactor = 1.0
    glyph.OrientationArray = ["POINTS", "No orientation array"]
    glyph.GlyphMode = "All Points"
    glyph.GlyphType.ThetaResolution = 24
    glyph.GlyphType.PhiResolution = 16
    glyph.UpdatePipeline(t_last)
    bounds = glyph.GetDataInformation().GetBounds()
    print(f"glyph bounds {[round(b, 5) for b in bounds]}")
    print(f"expected     {[round(b, 5) for b in expected['bounds']]}")
    # a tessellated sphere lies inside the true sphere, so allow 2 % of the largest radius
    tol = 0.02 * 0.006 + 1e-9
    if any(abs(a - b) > tol for a, b in zip(bounds, expected["bounds"])):
        problems.append(f"glyph bounds {bounds} != sphere extent {expected['bounds']}")

    disp = pv.Show(glyph, view)
    pv.ColorBy(disp, ("POINTS", "velocity", "Magnitude"))
    lut = pv.GetColorTransferFunction("velocity")
    lut.ApplyPreset("Cool to Warm", True)
    disp.RescaleTransferFunctionToDataRange(True, False)
    disp.SetScalarBarVisibility(view, True)
    bar = pv.GetScalarBar(lut, view)
    bar.Title = "velocity magnitude [m/s]"
    bar.ComponentTitle = ""
    bar.TitleColor = bar.LabelColor = [0.1, 0.1, 0.1]

    walls_pvd = folder / "walls.pvd"
    if walls_pvd.exists():
        walls = pv.PVDReader(FileName=str(walls_pvd))
        wdisp = pv.Show(walls, view)
        wdisp.ColorArrayName = ["POINTS", ""]
        wdisp.DiffuseColor = [0.6, 0.6, 0.6]
        wdisp.Opacity = 0.25
        walls.UpdatePipeline(t_last)
        n_cells = walls.GetDataInformation().GetNumberOfCells()
        print(f"walls: {n_cells} cells")
        if n_cells == 0:
            problems.append("walls.pvd has no cells")

    view.CameraPosition = [0.35, -0.28, 0.25]
    view.CameraFocalPoint = [0.05, 0.05, 0.06]
    view.CameraViewUp = [0, 0, 1]
    view.ResetCamera()
    pv.Render(view)
    pv.SaveScreenshot(str(png), view, ImageResolution=[900, 700])
    print(f"saved {png}")
    if problems:
        print("PROBLEMS:\n  " + "\n  ".join(problems))
        return 1
    print("ParaView check OK")
    return 0


if __name__ == "__main__":
    if len(sys.argv) >= 3 and sys.argv[1] == "make":
        make(sys.argv[2])
    elif len(sys.argv) >= 4 and sys.argv[1] == "render":
        rc = render(sys.argv[2], sys.argv[3])
        sys.stdout.flush()
        sys.stderr.flush()
        # skip interpreter teardown: pvbatch under Xvfb can die there with a GLXBadContext
        # X error (after the PNG is saved), which would turn a pass into exit code 1
        os._exit(rc)
    else:
        print(__doc__)
        sys.exit(2)
