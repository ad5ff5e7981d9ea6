"""Particle size distributions of the ``generate`` stage: the ``radius:`` key.

Four forms, picked by ``distribution:`` (a mapping without it is ``uniform``, the form that
predates the key). Radii r in m, diameters d = 2 r in m.

- ``uniform`` (min, max): r ~ U(min, max), number-weighted; min = max gives one size.
- ``lognormal``: ln r ~ N(mu, sigma^2), given as ``median`` (m) and geometric standard
  deviation ``gsd`` (mu = ln median, sigma = ln gsd) or as ``mu`` and ``sigma`` of ln(r / 1 m);
  with ``min``/``max`` truncated to [min, max] by inverse-CDF sampling,
  r = exp(mu + sigma Phi^-1(Phi(a) + u (Phi(b) - Phi(a)))), a = (ln min - mu) / sigma,
  b = (ln max - mu) / sigma, u ~ U(0, 1): exact, no rejection loop.
- ``sieve``: a sieve curve, apertures ``sieves`` (diameters, ascending) and mass percent
  ``passing`` (non-decreasing, 0 at the smallest sieve, 100 at the largest), as in the
  ``gradation`` stage. Class j between sieves a = d_(j-1) and b = d_j holds the mass share
  P_j = Q_j - Q_(j-1) (:func:`demcli.geometry.sieve.class_shares`). Inside a class the
  passing curve is taken linear in log d, the semi-log gradation chart: mass uniform in ln d,
  so the number density is n(d) ∝ d^-3 dm/dd ∝ d^-4 on [a, b]. Its inverse CDF is
  d = (a^-3 - u (a^-3 - b^-3))^(-1/3), and its mean d^3 per particle is
  <d^3>_j = 3 ln(b/a) / (a^-3 - b^-3); class j gets the number fraction
  f_j ∝ P_j / <d^3>_j. (Log-uniform mass keeps a wide class from being filled by its fines,
  and matches how a curve between two sieves is read off the chart.)
- ``discrete``: ``radii`` with ``fractions`` (summing to 1) ``by: mass`` (default; number
  fractions f_i ∝ w_i / r_i^3) or ``by: number`` (f_i = w_i).

Sieve classes and discrete sizes are stratified: class j gets round(N f_j) particles (largest
remainders, summing to N) and, in a sieve class of N_j, the k-th particle u = (k + U_k) / N_j;
the list is then shuffled. A small specimen so follows the curve to about one particle per
class instead of the multinomial +- sqrt(N f_j (1 - f_j)).
"""

import math

import numpy as np

from demcli.config.schema import Float, List, Optional, Section, Str, Tagged


def _check_uniform(node, report):
    if node.max < node.min:
        report("max", f"must be >= radius.min ({node.min:g} m)", node.max)


def _check_lognormal(node, report):
    pairs = {"median/gsd": (node.median, node.gsd), "mu/sigma": (node.mu, node.sigma)}
    given = [name for name, (a, b) in pairs.items() if a is not None or b is not None]
    if len(given) != 1:
        report("", "give either median and gsd or mu and sigma", ", ".join(given) or None)
        return
    for key, value in zip(given[0].split("/"), pairs[given[0]]):
        if value is None:
            report(key, f"required with {given[0].replace(key, '').strip('/')}")
    if node.min is not None and node.max is not None and node.max <= node.min:
        report("max", f"must be > min ({node.min:g} m)", node.max)


def _check_sieve(node, report):
    from demcli.stages.specimen.gradation import check_curve

    s, q = node.sieves, node.passing
    if not check_curve(s, q, report):
        return
    if q[0] != 0:
        report("passing.0", "must be 0 at the smallest sieve (it bounds the smallest class)", q[0])
    if q[-1] != 100:
        report(f"passing.{len(q) - 1}", "must be 100 at the largest sieve (it bounds the largest class)", q[-1])


def _check_discrete(node, report):
    if len(node.fractions) != len(node.radii):
        report("fractions", f"needs one value per radius ({len(node.radii)})", len(node.fractions))
        return
    total = sum(node.fractions)
    if abs(total - 1.0) > 1e-6:
        report("fractions", "must sum to 1", round(total, 9))


_POSITIVE = dict(min=0, min_inclusive=False)
SIZE = Tagged("distribution", {
    "uniform": Section({"min": Float("m", **_POSITIVE, doc="smallest radius"),
                        "max": Float("m", **_POSITIVE, doc="largest radius")},
                       doc="r uniform between min and max (number-weighted)", check=_check_uniform),
    "lognormal": Section({
        "median": Optional(Float("m", **_POSITIVE), doc="median radius exp(mu)"),
        "gsd": Optional(Float(min=1, min_inclusive=False), doc="geometric standard deviation exp(sigma)"),
        "mu": Optional(Float(), doc="mean of ln(r / 1 m)"),
        "sigma": Optional(Float(**_POSITIVE), doc="standard deviation of ln r"),
        "min": Optional(Float("m", **_POSITIVE), doc="truncation: smallest radius"),
        "max": Optional(Float("m", **_POSITIVE), doc="truncation: largest radius"),
    }, doc="ln r normal (by number), optionally truncated to [min, max]", check=_check_lognormal),
    "sieve": Section({
        "sieves": List(Float("m", **_POSITIVE), min_len=2, doc="square-hole apertures (diameters), ascending"),
        "passing": List(Float(min=0, max=100), min_len=2,
                        doc="mass percent passing each sieve: 0 at the first, 100 at the last"),
    }, doc="diameters following a sieve curve by mass (log-uniform mass inside each class)", check=_check_sieve),
    "discrete": Section({
        "radii": List(Float("m", **_POSITIVE), min_len=1, doc="the radii"),
        "fractions": List(Float(min=0, max=1), min_len=1, doc="share of each radius, summing to 1"),
        "by": Str(choices=["mass", "number"], default="mass", doc="what the fractions are shares of"),
    }, doc="a list of radii with mass or number fractions", check=_check_discrete),
}, default_tag="uniform", doc="particle radius distribution (without distribution: uniform between min and max)")


def _largest_remainder(fractions, n):
    """Integer counts (k,) summing to n, each within 1 of n f_j (Hamilton's method)."""
    exact = n * np.asarray(fractions, float) / np.sum(fractions)
    counts = np.floor(exact).astype(np.int64)
    short = n - int(counts.sum())
    if short > 0:
        counts[np.argsort(-(exact - counts), kind="stable")[:short]] += 1
    return counts


def sieve_classes(dist):
    """Classes of a sieve curve: lower and upper diameters (m) and number fractions f_j (sum 1)."""
    from demcli.geometry.sieve import class_shares

    s = np.asarray(dist.sieves, float)
    share = class_shares(s, dist.passing)[1:-1]  # the open classes are empty (0 % and 100 %)
    a, b = s[:-1], s[1:]
    mean_d3 = 3.0 * np.log(b / a) / (a ** -3.0 - b ** -3.0)
    f = share / mean_d3
    return a, b, f / f.sum()


def _draw_sieve(rng, dist, n):
    a, b, f = sieve_classes(dist)
    counts = _largest_remainder(f, n)
    parts = []
    for lo, hi, m in zip(a, b, counts):
        u = (np.arange(m) + rng.random(m)) / max(m, 1)
        parts.append((lo ** -3.0 - u * (lo ** -3.0 - hi ** -3.0)) ** (-1.0 / 3.0))
    return 0.5 * rng.permutation(np.concatenate(parts))


def _draw_discrete(rng, dist, n):
    r = np.asarray(dist.radii, float)
    w = np.asarray(dist.fractions, float)
    f = w / r ** 3 if dist.by == "mass" else w
    return rng.permutation(np.repeat(r, _largest_remainder(f, n)))


def lognormal_parameters(dist):
    """(mu, sigma) of ln(r / 1 m) of a lognormal distribution node."""
    if dist.median is not None:
        return math.log(dist.median), math.log(dist.gsd)
    return dist.mu, dist.sigma


def _draw_lognormal(rng, dist, n):
    from scipy.special import ndtr, ndtri

    mu, sigma = lognormal_parameters(dist)
    lo = ndtr((math.log(dist.min) - mu) / sigma) if dist.min is not None else 0.0
    hi = ndtr((math.log(dist.max) - mu) / sigma) if dist.max is not None else 1.0
    r = np.exp(mu + sigma * ndtri(lo + rng.random(n) * (hi - lo)))
    lower = dist.min if dist.min is not None else 0.0  # ndtri's rounding must not step out of [min, max]
    return np.clip(r, lower, dist.max if dist.max is not None else np.inf)


def draw_radii(rng, dist, n):
    """n radii (m) of the distribution node ``dist`` (the validated ``radius:``), drawn with ``rng``.

    ``uniform`` draws ``rng.uniform(min, max, n)`` exactly as before the other forms existed,
    so old cases give the same radii.
    """
    if dist.distribution == "uniform":
        return rng.uniform(dist.min, dist.max, n) if dist.max > dist.min else np.full(n, dist.min)
    return {"lognormal": _draw_lognormal, "sieve": _draw_sieve, "discrete": _draw_discrete}[
        dist.distribution](rng, dist, n)


def draw_amount(rng, dist, target, planar):
    """Radii (m) whose total volume 4/3 pi sum r^3 (m^3; 2D: area pi sum r^2, m^2) first reaches
    ``target``, overshooting by less than one particle.

    A pilot draw of 4096 radii gives the mean amount per particle, v_mean; then
    N = ceil(target / v_mean) radii are drawn in one (stratified) draw, topped up while short,
    and cut where the running sum first reaches the target. One draw of about N keeps a sieve
    curve's or discrete list's stratification (a cut removes a few particles at random).
    """
    power, factor = (2, math.pi) if planar else (3, 4.0 / 3.0 * math.pi)
    each = factor * float(np.mean(draw_radii(rng, dist, 4096) ** power))
    r = draw_radii(rng, dist, max(1, math.ceil(target / each)))
    while factor * float(np.sum(r ** power)) < target:
        short = target - factor * float(np.sum(r ** power))
        r = np.concatenate([r, draw_radii(rng, dist, max(16, math.ceil(short / each)))])
    n = int(np.searchsorted(np.cumsum(factor * r ** power), target)) + 1
    return r[:min(n, len(r))]


def radius_range(dist):
    """(smallest, largest) radius the distribution draws (m); an untruncated lognormal's open
    end is its 0.0001 (or 0.9999) quantile exp(mu -+ 3.719 sigma) (for the lattice spacing and
    the time-step estimate)."""
    if dist.distribution == "uniform":
        return dist.min, dist.max
    if dist.distribution == "sieve":
        return 0.5 * dist.sieves[0], 0.5 * dist.sieves[-1]
    if dist.distribution == "discrete":
        used = [r for r, w in zip(dist.radii, dist.fractions) if w > 0]
        return min(used), max(used)
    mu, sigma = lognormal_parameters(dist)
    lo = dist.min if dist.min is not None else math.exp(mu - 3.719 * sigma)
    return lo, dist.max if dist.max is not None else math.exp(mu + 3.719 * sigma)


def describe_size(dist):
    """A few words for ``demcli check``."""
    if dist.distribution == "uniform":
        return f"radius {dist.min:g}-{dist.max:g} m"
    if dist.distribution == "lognormal":
        mu, sigma = lognormal_parameters(dist)
        return f"lognormal radius (median {math.exp(mu):g} m, gsd {math.exp(sigma):.3g})"
    if dist.distribution == "sieve":
        return f"diameters {dist.sieves[0]:g}-{dist.sieves[-1]:g} m by a sieve curve"
    return f"{len(dist.radii)} radii by {dist.by}"
