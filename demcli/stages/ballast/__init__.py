"""Railway ballast stages (seed 002, Shao, Lian & Yang 2017): the polyhedron library, the graded
assembly, the ballast box (deposit, vibrate, sleeper) and polyhedra as sphere clumps (clumpify)."""
