"""Temperature sets of Burgers bond parameters: the ``temperatures`` key of the dynamic modulus
stage (issue #32).

The bonds as the stage gets them (its ``bonds`` models, else the input state's) are those at
the reference temperature T_r. A set at temperature T [degC] gives the Burgers parameters there
in one of two ways:

- by time-temperature superposition (the default): every viscosity of every Burgers bond model,
  C_m and C_k in tension (and compression) and in shear, is multiplied by a_T and the springs
  K_m, K_k (and k_n) are kept. A Burgers element's response depends on the frequency only
  through w C, so its modulus at (f, T) is the one at (f a_T, T_r): the shift is exact for the
  bonds, and the test of the master curve fit (tests/stages/test_dynamic_modulus.py). a_T is
  the set's ``shift_factor``, or follows from the ``shift`` rule, WLF (C_1, C_2) or Arrhenius
  (E_a) (:mod:`demcli.stages.asphalt.master_curve`); a set at T_r without either has a_T = 1;
- explicitly: ``models``, the tension and shear elements (K_m, C_m, K_k, C_k) of the Burgers
  model of each material pair named, measured or calibrated at T (springs may change with T
  too: a binder stiffens as it cools); models not named keep their T_r parameters.
"""

import math

import numpy as np

from demcli.config.schema import Float, List, Optional, Section, Str, Tagged
from demcli.errors import InputError
from demcli.kernels import bonds as B
from demcli.stages.asphalt.master_curve import FORMS, arrhenius_log_shift, wlf_log_shift
from demcli.stages.dem import BURGERS_ELEMENT

_T = {"unit": "degC", "min": -273.15, "min_inclusive": False}


def _check(node, report):
    """Cross-field rules: each set's source of parameters, T_r among the sets for free shifts,
    the WLF denominator positive over the sets."""
    temps = [s.temperature for s in node.sets]
    for k, s in enumerate(node.sets):
        if s.temperature == node.reference and (s.models is not None or s.shift_factor not in (None, 1.0)):
            report(f"sets.{k}", "the set at the reference temperature takes the bonds as given (a_T = 1): no models, "
                                "no shift_factor other than 1", s.temperature)
        elif s.shift_factor is not None and s.models is not None:
            report(f"sets.{k}", "give shift_factor or models, not both", s.temperature)
        elif s.shift_factor is None and s.models is None and node.shift is None and s.temperature != node.reference:
            report(f"sets.{k}", "needs shift_factor or models, or a shift rule (temperatures.shift) away from the "
                                f"reference temperature {node.reference:g} degC", s.temperature)
    if node.fit == "free" and len(temps) > 1 and node.reference not in temps:
        report("reference", "with fit: free the reference temperature must be one of the sets' (its a_T is 1); or "
                            "fit: wlf or arrhenius", node.reference)
    rule = node.shift
    if rule is not None and rule.rule == "wlf" and rule.c2 + min(temps) - node.reference <= 0:
        report("shift.c2", f"C_2 + T - T_r must be > 0 at every set's temperature (lowest {min(temps):g} degC)",
               rule.c2)


SET = Section({
    "temperature": Float(**_T, doc="T [degC]"),
    "shift_factor": Optional(Float(min=0, min_inclusive=False),
                             doc="a_T: every Burgers viscosity (C_m, C_k) times a_T, springs kept"),
    "models": Optional(List(Section({
        "materials": List(Str(), min_len=2, max_len=2, doc="the material pair of a Burgers bond model"),
        "tension": BURGERS_ELEMENT, "shear": BURGERS_ELEMENT}), min_len=1),
        doc="explicit Burgers elements at T per material pair (tension, also compression where the model says so; "
            "shear)"),
}, doc="one temperature: a_T (shift_factor or the shift rule) or explicit models")

TEMPERATURES = Optional(Section({
    "reference": Float(**_T, doc="T_r [degC]: the bonds as given are at T_r, where a_T = 1; the master curve's "
                                 "reference"),
    "shift": Optional(Tagged("rule", {
        "wlf": Section({"c1": Float(min=0, min_inclusive=False, doc="C_1"),
                        "c2": Float("K", min=0, min_inclusive=False,
                                    doc="C_2, a temperature difference: a plain number or in K (not degC, "
                                        "which converts as a temperature)")},
                       doc="log10 a_T = -C_1 (T - T_r) / (C_2 + T - T_r)"),
        "arrhenius": Section({"activation_energy": Float("J/mol", min=0, min_inclusive=False, doc="E_a")},
                             doc="log10 a_T = E_a / (ln(10) R) (1/T_K - 1/T_r,K)")}),
        doc="a_T of the sets that give neither shift_factor nor models"),
    "fit": Str(choices=FORMS, default="free", doc="the master curve's shift factors: free (one per temperature), or "
                                                  "constrained to the wlf or arrhenius form (its constants fitted)"),
    "sets": List(SET, min_len=1, unique_by="temperature", doc="the temperatures, run in the order given"),
}, check=_check), doc="run the frequency sweep at each temperature set from the same input; two or more: the "
                      "master curve (docs/asphalt_lab.md, 'Master curve')")


def log_shift(tset, tcfg):
    """log10 a_T a set applies to the viscosities (NaN for explicit ``models``)."""
    if tset.models is not None:
        return math.nan
    if tset.shift_factor is not None:
        return math.log10(tset.shift_factor)
    rule = tcfg.shift
    if rule is None:  # the reference temperature itself (validated)
        return 0.0
    if rule.rule == "wlf":
        return float(wlf_log_shift(tset.temperature, tcfg.reference, rule.c1, rule.c2))
    return float(arrhenius_log_shift(tset.temperature, tcfg.reference, rule.activation_energy))


def bond_table_at(prm, materials, tset, tcfg, names):
    """The bond-model table ``prm`` (n_bm, N_BPARAMS) [SI] with material pairs ``materials``
    (n_bm, 2) at the set's temperature: Burgers viscosities (B_CMN, B_CKN, B_CMS, B_CKS) times a_T,
    or the named pairs' tension and shear elements replaced (``names``: the case's material
    names, in index order). InputError for a named pair without a Burgers model."""
    burgers = prm[:, B.B_KIND] == B.BURGERS
    if tset.models is None:
        a_t = 10.0 ** log_shift(tset, tcfg)
        for col in (B.B_CMN, B.B_CKN, B.B_CMS, B.B_CKS):
            prm[burgers, col] *= a_t
        return prm
    for m in tset.models:
        pair = sorted(names.index(x) for x in m.materials)
        hit = np.nonzero(burgers & (materials[:, 0] == pair[0]) & (materials[:, 1] == pair[1]))[0]
        if not len(hit):
            raise InputError(f"temperatures: the set at {tset.temperature:g} degC names the pair "
                             f"{list(m.materials)}, which has no Burgers bond model in the stage")
        for col, part in ((B.B_KMN, m.tension), (B.B_KMS, m.shear)):
            prm[hit[0], col:col + 4] = part.km, part.cm, part.kk, part.ck
    return prm


def case_check(cfg, case, report):
    """The rules that need the stage and the case: enough points for the master curve's
    parameters (4 + the shifts') and the sets' material names."""
    tc = cfg.temperatures
    n_sets = len(tc.sets)
    n_par = 4 + {"free": n_sets - 1, "wlf": 2, "arrhenius": 1}[tc.fit]
    if n_sets > 1 and n_sets * len(cfg.frequencies) <= n_par:
        report("temperatures.sets", f"the master curve ({tc.fit} shifts) has {n_par} parameters: it needs more "
                                    f"points (temperatures x frequencies) than that", n_sets * len(cfg.frequencies))
    for k, s in enumerate(tc.sets):
        for j, m in enumerate(s.models or ()):
            for x in m.materials:
                if x not in case.materials:
                    report(f"temperatures.sets.{k}.models.{j}.materials", "unknown material", x)
