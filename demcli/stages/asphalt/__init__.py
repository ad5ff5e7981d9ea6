"""Asphalt stages: the 3D aggregate pipeline of seed 000 (place_spheres, carve, compact, cut,
mastic; shared pieces in :mod:`.common`), the 2D section of seed 001 (polygons, discretize) and
the bonded sand asphalt specimens of seed 003 (prepare, creep)."""
