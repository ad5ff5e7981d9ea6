"""Cycling a packing to static equilibrium: the shared step of radius expansion (seed 003's
bonded specimen, seed 000's dense seed spheres).

Equilibrium is judged as PFC judges it: the mean unbalanced force (the norm of each body's
resultant) over the mean contact force, below a ratio (1e-2 in the seeds' sense of "cycled to
equilibrium").
"""

import math

import numpy as np

from demcli import interrupts
from demcli.errors import StageError
from demcli.stepping import Stepper


def unbalanced(system):
    """Mean unbalanced force over mean contact force (inf without contacts)."""
    nl = system.nl
    fc = nl.fc[nl.act.astype(bool)]
    wfc = nl.wfc[:, :3]
    forces = np.concatenate([np.linalg.norm(fc, axis=1), np.linalg.norm(wfc, axis=1)])
    forces = forces[forces > 0]
    if len(forces) == 0:
        return math.inf
    return float(np.linalg.norm(system.f, axis=1).mean() / forces.mean())


def cycle_to_equilibrium(ctx, system, max_steps, ratio, what="packing"):
    """Step ``system`` in chunks of 200 until :func:`unbalanced` < ``ratio`` or ``max_steps``;
    returns the steps taken. Ctrl-C and SIGTERM act between chunks; an unstable step ends the
    stage with a StageError naming the step."""
    from demcli.kernels import layout as K

    done = 0
    with interrupts.deferred() as poll, Stepper(ctx, system) as stepper:
        while done < max_steps:
            status, k, _ = stepper.advance(min(200, max_steps - done))
            if status != K.OK:
                raise StageError(f"stage {ctx.name}: {what} went unstable ({K.STATUS_TEXT[status]}) at step "
                                 f"{system.step}; lower dt_factor or kn")
            done += k
            if unbalanced(system) < ratio:
                break
            poll()
    return done
