"""Stages that build a specimen for any material: the sieve table and class amounts
(gradation) and spheres or clumps placed in a region (generate)."""
