"""Unit conversion of case-file values (demcli.units)."""

import math
import subprocess
import sys

import pytest

from demcli.units import UnitError, describe_unit, format_si, to_si


@pytest.mark.parametrize(
    "text, unit, expected",
    [
        ("63 mm", "m", 0.063),
        ("40 kN", "N", 40_000.0),
        ("10 Hz", "Hz", 10.0),
        ("0.1 MPa", "Pa", 1.0e5),
        ("4e11 Pa", "Pa", 4.0e11),
        ("2.6 g/cm^3", "kg/m^3", 2600.0),
        ("2.6 g/cm3", "kg/m^3", 2600.0),
        ("1e5 N/m", "N/m", 1.0e5),
        ("9.81 m/s2", "m/s^2", 9.81),
        ("2 N*s/m", "N*s/m", 2.0),
        ("5 kN m", "N*m", 5000.0),
        ("30 deg", "rad", math.pi / 6),
        ("60 rpm", "rad/s", 2 * math.pi),
        ("0.5 Pa*s", "Pa*s", 0.5),
        ("-3mm", "m", -0.003),
        ("1_000 kg", "kg", 1000.0),
        ("1.5 us", "s", 1.5e-6),
    ],
)
def test_quantity_strings_convert_to_si(text, unit, expected):
    # Given a quantity string and the SI unit of the field
    # When it is converted
    value = to_si(text, unit)
    # Then the SI value comes back as a float
    assert isinstance(value, float)
    assert value == pytest.approx(expected, rel=1e-12)


@pytest.mark.parametrize("value, unit", [(0.063, "m"), (3, "N"), ("0.5", "1"), ("1e-5", "s"), (" 7 ", "kg")])
def test_plain_numbers_are_taken_as_si(value, unit):
    # Given a plain number (or a number-only string) for a field with any unit
    # When it is converted
    # Then it is unchanged, as a float
    assert to_si(value, unit) == float(value)


@pytest.mark.parametrize(
    "text, unit, message",
    [
        ("63 kg", "m", '"63 kg" has unit kilogram, which is not a length (expected m)'),
        ("40 kN", "Pa", "which is not a pressure (expected Pa)"),
        ("10 mm", "kg/m^3", "which is not a density"),
        ("30 deg", "1", "a plain number without unit is expected"),
        ("60 rpm", "Hz", "which is not a frequency (expected Hz)"),
        ("1 rad", "m", "which is not a length"),
    ],
)
def test_wrong_dimension_is_refused_with_a_readable_message(text, unit, message):
    # Given a quantity whose dimension does not match the field's unit
    # When it is converted
    # Then UnitError (a ValueError) explains what was expected
    with pytest.raises(UnitError, match=None) as info:
        to_si(text, unit)
    assert isinstance(info.value, ValueError)
    assert message in str(info.value)


@pytest.mark.parametrize(
    "text, message",
    [
        ("12 furlongz", "cannot parse \"12 furlongz\": unknown unit 'furlongz'"),
        ("mm", 'cannot parse "mm": expected a number'),
        ("1 m/", 'cannot parse "1 m/"'),
        ("fast", 'cannot parse "fast"'),
    ],
)
def test_unparseable_strings_are_refused(text, message):
    # Given a string that is not a number followed by a known unit
    # When it is converted
    # Then the error says it cannot be parsed, naming the string
    with pytest.raises(UnitError) as info:
        to_si(text, "m")
    assert message in str(info.value)


def test_percent_is_refused_with_the_fraction_suggested():
    # Given a dimensionless field written as a percentage
    # When it is converted
    # Then it is refused, and the message suggests the plain fraction
    with pytest.raises(UnitError, match=r"percent is not accepted.*\(0\.8\)"):
        to_si("80 %", "1")


@pytest.mark.parametrize("value", [True, None, [1, 2], {"a": 1}])
def test_non_numbers_are_refused(value):
    # Given something that is neither a number nor a string
    # When it is converted
    # Then UnitError is raised (booleans are not numbers)
    with pytest.raises(UnitError):
        to_si(value, "m")


@pytest.mark.parametrize(
    "value, unit, text",
    [(1.2e-5, "s", "1.2e-05 s"), (4e11, "Pa", "4e+11 Pa"), (0.063, "m", "0.063 m"),
     (2600.0, "kg/m^3", "2600 kg/m^3"), (0.3, "1", "0.3"), ((0.6, 0.3), "m", "[0.6, 0.3] m")],
)
def test_format_si(value, unit, text):
    # Given an SI value and its unit
    # When it is formatted
    # Then it reads compactly, with the unit unless dimensionless
    assert format_si(value, unit) == text


def test_describe_unit_names_what_a_unit_measures():
    # Given field units
    # When described
    # Then known ones have a name and unknown ones fall back to the unit
    assert describe_unit("N/m") == "a stiffness"
    assert describe_unit("kg/m**3") == "a density"
    assert describe_unit("N/m^5") == "a quantity in N/m^5"


def test_importing_units_does_not_import_pint():
    # Given a fresh interpreter
    # When demcli.units and demcli.config are imported and a plain number converted
    code = (
        "import sys, demcli.units, demcli.config; demcli.units.to_si(3, 'm');"
        "print('pint' in sys.modules)"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    # Then pint has not been loaded
    assert out.stdout.strip() == "False"
