"""Physical units for case files: quantities written with a unit become SI floats.

Every numeric field of a case is stored in one SI unit (``'m'``, ``'kg/m^3'``,
``'N*s/m'``, ``'1'`` for a plain number, ...). A value in the case file is either a
plain number, taken as already SI, or a string holding a number and a unit such as
``"63 mm"``, ``"40 kN"``, ``"2.6 g/cm3"`` or ``"30 deg"``; :func:`to_si` converts it.

The unit algebra is pint's. pint is imported and its registry built on the first
string that carries a unit, so ``import demcli.units`` stays cheap and a case
written in plain SI numbers never loads pint.

Rules beyond pint's own dimension check:

- exponents may be written glued to the unit (``cm3``, ``s2``, ``mm2``), as well as
  ``cm^3`` or ``cm**3``;
- percent (and per mille) is refused: a fraction is written as a plain number,
  because ``"80 %"`` next to a field documented as a fraction invites 80 vs 0.8 slips;
- angles must match: pint treats radians as dimensionless, so it would accept
  ``"30 deg"`` for a friction coefficient or ``"60 rpm"`` for a frequency in Hz
  (giving 2*pi per revolution). Here the power of radian in the given unit must
  equal the one in the field's unit; a plain number is still taken as SI.
"""

from __future__ import annotations

import functools
import math
import numbers
import re

__all__ = ["UnitError", "to_si", "format_si", "describe_unit"]


class UnitError(ValueError):
    """A value that cannot be read as a quantity in the expected unit."""


# A leading number (with optional exponent and digit separators), then the unit text.
_QUANTITY = re.compile(
    r"\s*([-+]?(?:\d[\d_]*(?:\.[\d_]*)?|\.\d[\d_]*)(?:[eE][-+]?\d+)?)\s*(.*?)\s*",
    re.S,
)
# An exponent glued to a unit name: cm3 -> cm**3, s2 -> s**2 (but H2O stays).
_GLUED_EXPONENT = re.compile(r"(?<=[A-Za-zµμΩ])(\d+)(?![\w.])")
_PERCENT_UNITS = {"percent", "permille"}

# What a field's unit measures, for messages ("which is not a length").
_KINDS = {
    "m": "a length",
    "m^2": "an area",
    "m^3": "a volume",
    "kg": "a mass",
    "s": "a time",
    "N": "a force",
    "Pa": "a pressure",
    "Hz": "a frequency",
    "1/s": "a rate",
    "kg/m^3": "a density",
    "m/s": "a velocity",
    "m/s^2": "an acceleration",
    "N/m": "a stiffness",
    "N/m^3": "a stiffness per area",
    "Pa/m": "a stiffness per area",
    "N*s/m": "a damping coefficient",
    "N*m": "a moment",
    "N*m/rad": "a rotational stiffness",
    "J": "an energy",
    "W": "a power",
    "rad": "an angle",
    "rad/s": "an angular velocity",
    "rad/s^2": "an angular acceleration",
    "Pa*s": "a viscosity",
    "kg*m^2": "a moment of inertia",
    "K": "a temperature",
    "1": "a plain number",
}

_registry = None


def _ureg():
    """The one pint registry, created on first use."""
    global _registry
    if _registry is None:
        import pint

        try:  # pint's parsed-definitions cache (~/.cache/pint): 0.2 s less per process
            _registry = pint.UnitRegistry(cache_folder=":auto:")
        except OSError:  # an unwritable cache folder
            _registry = pint.UnitRegistry()
    return _registry


@functools.lru_cache(maxsize=512)
def _parse_unit(text):
    """Parse a unit expression into ``(pint.Unit, radian_power, is_percent)``; cached."""
    ureg = _ureg()
    expr = _GLUED_EXPONENT.sub(r"**\1", text.strip())
    if expr in ("", "1"):
        expr = "dimensionless"
    try:
        unit = ureg.parse_units(expr)
    except Exception as exc:  # pint raises several types (undefined, syntax, tokenizer)
        name = getattr(exc, "unit_names", None)
        if isinstance(name, (list, tuple)) and name:
            name = name[0]
        if isinstance(name, str) and name:
            raise UnitError(f"unknown unit {name!r}") from None
        raise UnitError(f"not a unit expression: {text!r}") from None
    radians = dict(ureg.get_root_units(unit)[1]._units).get("radian", 0)
    percent = any(name in _PERCENT_UNITS for name in unit._units)
    return unit, radians, percent


def describe_unit(unit):
    """What a field unit measures, e.g. ``'a length'`` for ``'m'``."""
    key = unit.replace(" ", "").replace("**", "^")
    return _KINDS.get(key, f"a quantity in {unit}")


def to_si(value, unit="1"):
    """Return ``value`` as a float in the SI unit ``unit``.

    ``value`` is a plain number (taken as already SI) or a string: a number alone
    (``"1e-5"``, also SI) or a number followed by a unit (``"63 mm"``, ``"2.6 g/cm3"``).
    ``unit`` is the field's SI unit, ``'1'`` for a plain number.

    Raises :class:`UnitError` for anything else, with messages such as
    ``"63 kg" has unit kilogram, which is not a length (expected m)``.
    """
    if isinstance(value, bool):
        raise UnitError(f"expected a number, got {str(value).lower()}")
    if isinstance(value, numbers.Real):
        return float(value)
    if not isinstance(value, str):
        raise UnitError(f"expected a number or a quantity string, got {type(value).__name__}")
    match = _QUANTITY.fullmatch(value)
    if match is None:
        raise UnitError(f'cannot parse "{value}": expected a number, optionally followed by a unit')
    magnitude = float(match.group(1).replace("_", ""))
    unit_text = match.group(2)
    if not unit_text:
        return magnitude
    try:
        src, src_rad, src_percent = _parse_unit(unit_text)
    except UnitError as exc:
        raise UnitError(f'cannot parse "{value}": {exc}') from None
    dst, dst_rad, _ = _parse_unit(unit)
    if src_percent:
        fraction = _ureg().Quantity(magnitude, src).to("dimensionless").magnitude
        raise UnitError(
            f'"{value}": percent is not accepted; write the fraction as a plain number ({fraction:g})'
        )
    if src.dimensionality != dst.dimensionality or src_rad != dst_rad:
        if unit in ("1", ""):
            raise UnitError(f'"{value}" has unit {src}, but a plain number without unit is expected')
        raise UnitError(
            f'"{value}" has unit {src}, which is not {describe_unit(unit)} (expected {unit})'
        )
    result = float(_ureg().Quantity(magnitude, src).to(dst).magnitude)
    if not math.isfinite(result):
        raise UnitError(f'"{value}" is not a finite number')
    return result


def _format_number(x, digits):
    if x == 0 or not math.isfinite(x) or 1e-4 <= abs(x) < 1e6:
        return f"{x:.{digits}g}"
    mantissa, exponent = f"{x:.{digits - 1}e}".split("e")
    if "." in mantissa:
        mantissa = mantissa.rstrip("0").rstrip(".")
    return f"{mantissa}e{exponent}"


def format_si(value, unit="1", digits=12):
    """Format an SI value for people: ``format_si(1.2e-5, 's') == '1.2e-05 s'``.

    ``digits`` significant digits (trailing zeros dropped); no unit for ``'1'``.
    A sequence of numbers prints as ``[0.6, 0.3] m``.
    """
    if isinstance(value, (list, tuple)):
        text = "[" + ", ".join(format_si(v, "1", digits) for v in value) + "]"
    elif isinstance(value, bool) or not isinstance(value, numbers.Real):
        text = str(value)
    else:
        text = _format_number(float(value), digits)
    return text if unit in ("1", "") else f"{text} {unit}"
