"""The dynamic modulus master curve over several temperatures (issue #32): time-temperature
shift factors and the sigmoidal fit, its records and its figure.

Time-temperature superposition: the modulus at temperature T and frequency f equals the one at
the reference temperature T_r and the reduced frequency f_r = f a_T,

    |E*|(f, T) = |E*|(f a_T(T), T_r),         a_T(T_r) = 1,

a_T > 1 below T_r (stiffer, as if loaded faster). The master curve is the standard sigmoid
(AASHTO R 84, MEPDG: Pellinen & Witczak 2002) in log10 of the modulus [Pa]:

    log10 |E*| = delta + alpha / (1 + exp(beta + gamma log10 f_r)),

delta the lower asymptote, delta + alpha the upper one (gamma < 0: stiffer at higher f_r).
The shift factors are fitted together with the sigmoid (scipy least squares on log10 |E*|):
free (one log a_T per temperature, 0 at T_r, which must then be a tested temperature) or
constrained to a form (temperatures in degC, T_K = T + 273.15):

    WLF (Williams, Landel & Ferry 1955):  log10 a_T = -C_1 (T - T_r) / (C_2 + T - T_r)
    Arrhenius:                            log10 a_T = E_a / (ln(10) R) (1 / T_K - 1 / T_r,K)

with R = 8.314462618 J/(mol K) and E_a [J/mol]. The same forms give the shift of the bonds'
viscosities in a stage's temperature sets (:mod:`demcli.stages.asphalt.dynamic_modulus`).
"""

import math
from dataclasses import dataclass

import numpy as np

from demcli.state.records import RecordTable, describe_column

R_GAS = 8.314462618         # J/(mol K)
KELVIN = 273.15             # K at 0 degC
FORMS = ("free", "wlf", "arrhenius")

describe_column("temperature", "Temperature", "degC", table="dynamic_modulus", doc="test temperature (set)")
for _table in ("master_curve", "shift_factors"):
    describe_column("temperature", "Temperature", "degC", table=_table, doc="test temperature (set)")
describe_column("reduced_frequency", "Reduced frequency", "Hz", table="master_curve",
                doc="f a_T: the frequency at the reference temperature with the same modulus")
describe_column("fitted_modulus", "Fitted dynamic modulus", "Pa", "MPa", 1e-6, table="master_curve",
                doc="the sigmoidal master curve at the reduced frequency")
describe_column("log_shift_factor", "Shift factor log10 a_T", table="shift_factors",
                doc="log10 a_T fitted with the master curve")
for _name, _label, _unit, _doc in [
        ("delta", "Sigmoid delta", "1", "lower asymptote, log10 of |E*| in Pa"),
        ("alpha", "Sigmoid alpha", "1", "upper minus lower asymptote, log10"),
        ("beta", "Sigmoid beta", "1", "location: the midpoint at log10 f_r = -beta / gamma"),
        ("gamma", "Sigmoid gamma", "1", "steepness per decade of f_r (negative: stiffer when faster)"),
        ("reference_temperature", "Reference temperature", "degC", "T_r, where a_T = 1"),
        ("c1", "WLF C_1", "1", "fitted (fit: wlf), else NaN"), ("c2", "WLF C_2", "K", "fitted (fit: wlf), else NaN"),
        ("activation_energy", "Activation energy", "J/mol", "fitted (fit: arrhenius), else NaN"),
        ("rms_residual", "RMS residual", "1", "of log10 |E*| about the curve")]:
    describe_column(_name, _label, _unit, table="master_curve_fit", doc=_doc)
describe_column("applied_log_shift_factor", "Applied log10 a_T", table="shift_factors",
                doc="log10 a_T the temperature set applied to the bonds' viscosities (NaN: explicit parameters)")


def wlf_log_shift(t, t_ref, c1, c2):
    """log10 a_T = -C_1 (T - T_r) / (C_2 + T - T_r) (T, T_r, C_2 [degC or K differences], C_1 [-])."""
    dt = np.asarray(t, float) - t_ref
    return -c1 * dt / (c2 + dt)


def arrhenius_log_shift(t, t_ref, activation_energy):
    """log10 a_T = E_a / (ln(10) R) (1 / T_K - 1 / T_r,K) (T, T_r [degC], E_a [J/mol])."""
    tk = np.asarray(t, float) + KELVIN
    return activation_energy / (math.log(10.0) * R_GAS) * (1.0 / tk - 1.0 / (t_ref + KELVIN))


def sigmoid(log_fr, delta, alpha, beta, gamma):
    """log10 |E*| [log10 Pa] = delta + alpha / (1 + exp(beta + gamma log10 f_r)), f_r [Hz]."""
    z = np.clip(beta + gamma * np.asarray(log_fr, float), -700.0, 700.0)
    return delta + alpha / (1.0 + np.exp(z))


@dataclass
class MasterCurve:
    """A fitted master curve: sigmoid (delta, alpha [log10 Pa], beta, gamma [-]), the shift form
    and its constants (wlf: (C_1, C_2 [degC]); arrhenius: (E_a [J/mol],); free: ()), the
    reference temperature and the distinct temperatures [degC], their log10 a_T, and the rms
    residual of log10 |E*| over the points."""

    sigmoid: tuple
    form: str
    constants: tuple
    reference: float
    temperatures: np.ndarray
    log_shift: np.ndarray
    rms: float

    def shift_of(self, t):
        """log10 a_T at each temperature of ``t`` (one of the fitted temperatures) [-]."""
        return np.array([self.log_shift[int(np.argmin(np.abs(self.temperatures - x)))] for x in np.ravel(t)])

    def modulus(self, reduced_frequency):
        """|E*| [Pa] on the master curve at reduced frequencies [Hz]."""
        return 10.0 ** sigmoid(np.log10(reduced_frequency), *self.sigmoid)


def _shifts(form, p, temps, t_ref):
    """log10 a_T of ``temps`` from the shift parameters ``p`` of ``form`` (free: log a_T of the
    temperatures other than T_r, in order; wlf: C_1, C_2; arrhenius: E_a in kJ/mol)."""
    if form == "wlf":
        return wlf_log_shift(temps, t_ref, p[0], p[1])
    if form == "arrhenius":
        return arrhenius_log_shift(temps, t_ref, 1e3 * p[0])
    out = np.zeros(len(temps))
    out[np.abs(temps - t_ref) > 1e-9] = p
    return out


def _start(temps, t_ref, logf, y, which):
    """Starting values: each temperature shifted onto a straight line through the reference
    (or the middle) temperature's points, then the sigmoid through that cloud."""
    k0 = int(np.argmin(np.abs(temps - t_ref)))
    ref = which == k0
    slope, icpt = np.polyfit(logf[ref], y[ref], 1) if np.ptp(logf[ref]) > 0 else (0.3, float(np.mean(y[ref])))
    slope = slope if abs(slope) > 1e-3 else 0.3
    shift = np.array([(np.mean(y[which == k]) - icpt) / slope - np.mean(logf[which == k])
                      for k in range(len(temps))])
    shift -= shift[k0]
    x = logf + shift[which]
    span = float(np.ptp(y)) + 1.0
    gamma = -min(4.0 * abs(slope) / span, 5.0)
    return shift, [float(np.min(y)) - 0.5, span, -gamma * float(np.mean(x)), gamma]


def fit_master_curve(temperature, frequency, modulus, reference, form="free"):
    """Fit the sigmoid and the shift factors (module doc) to measured points: ``temperature``
    [degC], ``frequency`` [Hz] and ``modulus`` [Pa] per point; ``reference`` T_r [degC];
    ``form``: free, wlf or arrhenius. Least squares on log10 |E*| (scipy ``least_squares``),
    started from the free fit for a constrained form. Returns a :class:`MasterCurve`.

    ValueError: fewer points than parameters, or (free) T_r not one of the temperatures."""
    from scipy.optimize import least_squares

    t, logf, y = (np.asarray(a, float) for a in (temperature, np.log10(frequency), np.log10(modulus)))
    temps = np.array(list(dict.fromkeys(t.tolist())))
    which = np.array([int(np.argmin(np.abs(temps - x))) for x in t])
    n_shift = {"free": len(temps) - 1, "wlf": 2, "arrhenius": 1}[form]
    if len(y) <= 4 + n_shift:
        raise ValueError(f"the master curve ({form} shifts) has {4 + n_shift} parameters: it needs more points "
                         f"(temperatures x frequencies) than that, has {len(y)}")
    if form == "free" and np.min(np.abs(temps - reference)) > 1e-9:
        raise ValueError(f"free shift factors need the reference temperature {reference:g} degC among the "
                         "temperatures tested")
    shift, sig = _start(temps, reference, logf, y, which)

    def residual(p, form_):
        return sigmoid(logf + _shifts(form_, p[4:], temps, reference)[which], *p[:4]) - y

    if form == "free" or np.min(np.abs(temps - reference)) < 1e-9:
        free = least_squares(residual, sig + [s for k, s in enumerate(shift) if abs(temps[k] - reference) > 1e-9],
                             args=("free",), method="lm", max_nfev=20000)
        sig, shift = list(free.x[:4]), _shifts("free", free.x[4:], temps, reference)
    p = free.x if form == "free" else _constrained(residual, form, sig, shift, temps, reference)
    logs = _shifts(form, p[4:], temps, reference)
    consts = tuple(float(c) * (1e3 if form == "arrhenius" else 1.0) for c in p[4:]) if form != "free" else ()
    return MasterCurve(tuple(float(v) for v in p[:4]), form, consts, float(reference), temps, logs,
                       float(np.sqrt(np.mean(residual(p, form) ** 2))))


def _constrained(residual, form, sig, shift, temps, t_ref):
    """The joint fit with the shifts of ``form``, its constants started from a fit of the form
    to the free shifts ``shift`` (C_1 = 19, C_2 = 92 degC, E_a = 200 kJ/mol when there are none)."""
    from scipy.optimize import least_squares

    dt = temps - t_ref
    if form == "wlf":
        lo = [-np.inf, float(max(0.0, -dt.min())) + 1.0]
        start = least_squares(lambda c: wlf_log_shift(temps, t_ref, *c) - shift, [19.0, max(92.0, lo[1] + 10.0)],
                              bounds=(lo, [np.inf, np.inf])).x
    else:
        lo = [-np.inf]
        start = least_squares(lambda c: arrhenius_log_shift(temps, t_ref, 1e3 * c[0]) - shift, [200.0]).x
    bounds = ([-np.inf] * 4 + lo, [np.inf] * (4 + len(lo)))
    return least_squares(residual, list(sig) + list(start), args=(form,), bounds=bounds, max_nfev=20000).x


def superposition_warnings(curve, rows, applied, tolerance=0.1):
    """What says the points are no master curve, in words: a temperature whose |E*| falls
    between two frequencies by more than the larger fit residual / amplitude of the two (a
    viscoelastic solid's rises with f; a specimen that changes during the sweep, e.g. stiffens
    as it creeps, need not), and fitted log10 a_T further than ``tolerance`` from the applied
    one (``applied``: {T: log10 a_T or NaN}; for a network of springs and dashpots whose
    viscosities all scale by a_T they agree up to the inertia). ``rows``: the stage's result
    rows (temperature, frequency, modulus, fit_residual)."""
    out = []
    for t in curve.temperatures:
        pts = sorted((r["frequency"], r["modulus"], r["fit_residual"]) for r in rows if r["temperature"] == t)
        if any(b[1] < a[1] * (1 - max(a[2], b[2])) for a, b in zip(pts, pts[1:])):
            out.append(f"at {t:g} degC |E*| does not rise with the frequency (" +
                       ", ".join(f"{m / 1e6:.4g} MPa at {f:g} Hz" for f, m, _ in pts) +
                       "): the specimen changes during the sweep; time-temperature superposition does not hold")
    for t, s in zip(curve.temperatures, curve.log_shift):
        a = applied.get(float(t), math.nan)
        if abs(s - a) > tolerance:
            out.append(f"at {t:g} degC the fitted log10 a_T {s:+.4g} is {s - a:+.3g} from the applied {a:+.4g}: the "
                       "points do not superpose as the bonds' shift predicts")
    return out


def master_curve_tables(curve, rows, applied):
    """The records of a fitted curve: ``master_curve`` (per measured point: temperature [degC],
    frequency, reduced frequency [Hz], |E*| [Pa], phase angle [deg], fitted |E*| [Pa]),
    ``shift_factors`` (per temperature: fitted and ``applied`` log10 a_T, {T: value or NaN}) and
    ``master_curve_fit`` (one row: the sigmoid, T_r, the form's constants or NaN, the rms residual).
    ``rows``: the stage's result rows (temperature, frequency, modulus, phase_angle)."""
    pts = RecordTable("master_curve", {"temperature": "degC", "frequency": "Hz", "reduced_frequency": "Hz",
                                       "modulus": "Pa", "phase_angle": "deg", "fitted_modulus": "Pa"})
    for r in rows:
        fr = r["frequency"] * 10.0 ** float(curve.shift_of(r["temperature"])[0])
        pts.append(temperature=r["temperature"], frequency=r["frequency"], reduced_frequency=fr,
                   modulus=r["modulus"], phase_angle=r["phase_angle"], fitted_modulus=float(curve.modulus(fr)))
    shifts = RecordTable("shift_factors", {"temperature": "degC", "log_shift_factor": "1",
                                           "applied_log_shift_factor": "1"})
    for t, s in zip(curve.temperatures, curve.log_shift):
        shifts.append(temperature=t, log_shift_factor=s, applied_log_shift_factor=applied.get(float(t), math.nan))
    c = dict(zip(("c1", "c2") if curve.form == "wlf" else ("activation_energy",), curve.constants))
    fit = RecordTable("master_curve_fit", {"delta": "1", "alpha": "1", "beta": "1", "gamma": "1",
                                           "reference_temperature": "degC", "c1": "1", "c2": "K",
                                           "activation_energy": "J/mol", "rms_residual": "1"})
    fit.append(dict(zip(("delta", "alpha", "beta", "gamma"), curve.sigmoid)), reference_temperature=curve.reference,
               c1=c.get("c1", math.nan), c2=c.get("c2", math.nan),
               activation_energy=c.get("activation_energy", math.nan), rms_residual=curve.rms)
    return pts, shifts, fit


def master_curve_figure(curve, pts, shifts, title=""):
    """Two panels (None without matplotlib): |E*| [MPa] against the reduced frequency [Hz],
    log-log, the points of each temperature and the fitted sigmoid; log10 a_T against the
    temperature, fitted (with the form's curve) and as applied to the bonds."""
    try:
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure
    except ImportError:
        return None
    from demcli.state.plots import DPI, FONT

    p, s = pts.to_arrays(), shifts.to_arrays()
    fig = Figure(figsize=(10.5, 4.2), dpi=DPI)
    FigureCanvasAgg(fig)
    ax, bx = fig.add_subplot(1, 2, 1), fig.add_subplot(1, 2, 2)
    for t in curve.temperatures:
        sel = np.abs(p["temperature"] - t) < 1e-9
        ax.loglog(p["reduced_frequency"][sel], p["modulus"][sel] * 1e-6, "o", markersize=5, label=f"{t:g} °C")
    fr = np.logspace(np.log10(p["reduced_frequency"].min()) - 0.5, np.log10(p["reduced_frequency"].max()) + 0.5, 200)
    ax.loglog(fr, curve.modulus(fr) * 1e-6, "k-", linewidth=1.3, label=f"sigmoid, {curve.reference:g} °C")
    ax.set_xlabel("Reduced frequency f·a_T (Hz)", fontsize=FONT["label"])
    ax.set_ylabel("Dynamic modulus |E*| (MPa)", fontsize=FONT["label"])
    ax.legend(fontsize=FONT["legend"])
    bx.plot(s["temperature"], s["log_shift_factor"], "o", label=f"fitted ({curve.form})")
    if np.any(np.isfinite(s["applied_log_shift_factor"])):
        bx.plot(s["temperature"], s["applied_log_shift_factor"], "x", markersize=8, color="0.3", label="applied")
    if curve.form != "free":
        tt = np.linspace(s["temperature"].min(), s["temperature"].max(), 100)
        bx.plot(tt, _shifts(curve.form, [c / (1e3 if curve.form == "arrhenius" else 1) for c in curve.constants],
                            tt, curve.reference), "-", color="C0", linewidth=1.0)
    bx.set_xlabel("Temperature (°C)", fontsize=FONT["label"])
    bx.set_ylabel("Shift factor log₁₀ a_T", fontsize=FONT["label"])
    bx.legend(fontsize=FONT["legend"])
    from matplotlib.ticker import FuncFormatter

    for axis in (ax.yaxis.set_major_formatter, ax.yaxis.set_minor_formatter):  # 40, 50, 60 rather than 4 x 10^1
        axis(FuncFormatter(lambda v, _: f"{v:g}"))
    for a in (ax, bx):
        a.grid(True, alpha=0.3, which="both")
        a.tick_params(labelsize=FONT["tick"])
    if title:
        fig.suptitle(title, fontsize=FONT["title"])
    fig.tight_layout()
    return fig
