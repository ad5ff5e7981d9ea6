"""Write ``marshall_head.stl``: the lower breaking head of a Marshall stability test as a mesh wall.

The head is the inner face of a cylindrical arc that cradles a specimen of diameter
101.6 mm (ASTM D6927): radius 50.8 mm about the y axis (the specimen's axis lies along
y in the test), spanning +-40 degrees about -z (below the specimen), 76.2 mm long along y
and centred at the origin, in millimetres (``scale: 0.001`` in a case). Normals point
inwards (towards the axis). The upper head is the same file rotated 180 degrees about y.

    python cases/meshes/make_marshall_head.py     # rewrites marshall_head.stl beside this script
"""

from pathlib import Path

import meshio
import numpy as np

RADIUS = 50.8       # mm
HALF_ANGLE = 40.0   # degrees either side of -z
LENGTH = 76.2       # mm along y
ARC_SEGMENTS = 16
AXIAL_SEGMENTS = 4


def head_mesh():
    """(points (n, 3) mm, triangles (m, 3)) of the arc, wound so that normals point to the axis."""
    phi = np.radians(np.linspace(-HALF_ANGLE, HALF_ANGLE, ARC_SEGMENTS + 1))
    ys = np.linspace(-LENGTH / 2, LENGTH / 2, AXIAL_SEGMENTS + 1)
    pts = np.array([[RADIUS * np.sin(p), y, -RADIUS * np.cos(p)] for y in ys for p in phi])
    row = ARC_SEGMENTS + 1
    tris = []
    for j in range(AXIAL_SEGMENTS):
        for i in range(ARC_SEGMENTS):
            a, b, c, d = j * row + i, j * row + i + 1, (j + 1) * row + i + 1, (j + 1) * row + i
            tris += [(a, b, c), (a, c, d)]
    return pts, np.array(tris, np.int64)


def main():
    pts, tris = head_mesh()
    path = Path(__file__).with_name("marshall_head.stl")
    meshio.write(path, meshio.Mesh(pts, [("triangle", tris)]), file_format="stl", binary=True)
    print(f"{path}: {len(tris)} triangles")


if __name__ == "__main__":
    main()
