"""What researchers measure in a dynamic stage (issue #33, docs/measure.md).

* :mod:`demcli.measure.regions`: the ``measure:`` regions of a dem stage (sphere, box, cylinder,
  the whole specimen): which bodies lie in them and their volume;
* :mod:`demcli.measure.contacts`: the contacts of a sphere, clump or polyhedron scene as arrays
  (both sides of each pair, bonds included);
* :mod:`demcli.measure.tensors`: Love-Weber stress, fabric, coordination and velocity statistics
  of a set of bodies and contacts (numpy, no state);
* :mod:`demcli.measure.probe`: the per-region record tables and their figure;
* :mod:`demcli.measure.forcechain`: the contact network as VTU line cells (``output.force_chains``);
* :mod:`demcli.measure.coarse` and :mod:`demcli.measure.cg_kernels`: coarse-grained density,
  velocity and stress fields on a grid (``output.fields``);
* :mod:`demcli.measure.stage`: what the dem stage loop calls.

Importing this package compiles nothing; the coarse-graining kernels compile on first use.
"""
