"""Units a file states, read and applied (issue 22, item 3).

The interchange format stores SI units (rad, N m, s; docs/spec/log-format.md). A lab file
may state other units in three places, and every reader applies them the same way:

- the metadata key ``"units"``: ``{"theta": "deg", "tau_h[2]": "N mm", "t": "ms"}``, a
  signal name applying to every joint's column, a column name to that column only;
- a CSV column header with the unit after the name: ``theta[1] (deg)``, ``tau_h[1] [N m]``
  (a tail that is no known unit, ``tau_h[1] (raw)``, leaves the column an extra one);
- an NLID ``nldat`` object's ``chanUnits`` (trialformat.nlid).

Each stated unit is converted to SI on reading (a factor per column) and recorded in the
metadata key ``"units_read"`` (``{"theta[1]": {"unit": "deg", "stated_by": "column
header", "factor": 0.0174533}}``); the ``"units"`` key is then removed, so a trial written
back (in SI) is not converted twice. A unit this module does not know is refused, naming
the file, the column and the unit; "not stated" spellings (``Default Units``, ``none``,
empty) leave the column in SI.
"""

from __future__ import annotations

import math
import re

from .errors import TrialFormatError

ANGLE = {"rad": 1.0, "radian": 1.0, "radians": 1.0, "mrad": 1e-3,
         "deg": math.pi / 180, "degree": math.pi / 180, "degrees": math.pi / 180,
         "°": math.pi / 180}
TORQUE = {"nm": 1.0, "n m": 1.0, "n.m": 1.0, "n*m": 1.0, "n·m": 1.0, "n-m": 1.0,
          "nmm": 1e-3, "n mm": 1e-3, "n.mm": 1e-3, "n*mm": 1e-3, "n·mm": 1e-3,
          "mnm": 1e-3, "mn m": 1e-3, "mn.m": 1e-3, "mn*m": 1e-3, "mn·m": 1e-3,
          "ncm": 1e-2, "n cm": 1e-2, "n.cm": 1e-2, "n*cm": 1e-2}
TIME = {"s": 1.0, "sec": 1.0, "second": 1.0, "seconds": 1.0, "ms": 1e-3}
#: signal -> (known units, the SI unit)
KIND = {"theta": (ANGLE, "rad"), "theta_ref": (ANGLE, "rad"), "tau_h": (TORQUE, "N m"),
        "tau_delta": (TORQUE, "N m"), "tau_m": (TORQUE, "N m"), "t": (TIME, "s")}
NOT_STATED = ("", "default units", "default", "none", "unknown", "-")
_HEADER = re.compile(r"^\s*((?:" + "|".join(k for k in KIND if k != "t")
                     + r")\[\d+\]|t)\s*[\(\[]\s*([^\)\]]*?)\s*[\)\]]\s*$")
_COLUMN = re.compile(r"^(" + "|".join(KIND) + r")(?:\[(\d+)\])?$")


def split_header(name: str) -> tuple[str, str | None]:
    """``"theta[1] (deg)"`` -> ``("theta[1]", "deg")``; a plain name, or a tail that is no
    unit known for the signal (``"tau_h[1] (raw)"``: an extra column), -> ``(name, None)``."""
    m = _HEADER.match(name)
    if not m:
        return name, None
    try:
        factor(m.group(1), m.group(2), "")
    except TrialFormatError:
        return name, None
    return m.group(1), m.group(2)


def factor(column: str, unit: str, where) -> float | None:
    """The factor from ``unit`` to SI for ``column`` (``theta[1]``, ``t``); None when the
    unit is a "not stated" spelling.

    Raises
    ------
    TrialFormatError
        A unit not known for that signal, naming ``where``, the column and the unit.
    """
    text = " ".join(str(unit).strip().strip("()[]").split()).lower()
    if text in NOT_STATED:
        return None
    signal = _COLUMN.match(column).group(1)
    known, si = KIND[signal]
    if text not in known:
        raise TrialFormatError(
            f"{where}: column {column}: unit {unit!r} is not known for {signal} (known: "
            f"{', '.join(sorted(k for k in known if k.isascii()))}; stored in {si})")
    return known[text]


def stated_units(meta: dict, header_units: dict, where, *, by: str = "column header"
                 ) -> dict:
    """``{column: (unit, stated_by)}`` of every unit the file states: the metadata's
    ``units`` (signal or column keys) and ``header_units`` (``{column: unit}``, from the
    headers or ``chanUnits``; ``by`` says which).

    Raises
    ------
    TrialFormatError
        ``units`` not an object, a key that names no signal or column, or two places that
        state different units for one column.
    """
    out = {}
    declared = meta.get("units", {})
    if declared is None:
        declared = {}
    if not isinstance(declared, dict):
        raise TrialFormatError(f"{where}: key 'units' must be an object, e.g. "
                               f'{{"theta": "deg"}}, got {declared!r}')
    for key, unit in declared.items():
        m = _COLUMN.match(str(key))
        if not m or not isinstance(unit, str):
            raise TrialFormatError(
                f"{where}: key 'units.{key}' must name a signal ({', '.join(KIND)}) or a "
                f"column (theta[1], ...) and give a unit string, got {unit!r}")
        out[str(key)] = (unit, "metadata 'units'")
    for column, unit in header_units.items():
        signal = _COLUMN.match(column).group(1)
        for key in (column, signal):
            if key in out and _norm(out[key][0]) != _norm(unit) and \
                    factor(column, unit, where) != factor(column, out[key][0], where):
                raise TrialFormatError(
                    f"{where}: column {column}: the {by} states {unit!r} but key "
                    f"'units.{key}' states {out[key][0]!r}; state one")
        out[column] = (unit, by)
    return out


def _norm(unit) -> str:
    return " ".join(str(unit).split()).lower()


def apply_units(meta: dict, arrays: dict, header_units: dict, where, *,
                by: str = "column header") -> None:
    """Convert ``arrays`` (``t`` (N,), signal arrays (N, n)) to SI in place by the units
    the file states (:func:`stated_units`); record them in ``meta["units_read"]`` and
    remove ``meta["units"]``.

    Raises
    ------
    TrialFormatError
        As :func:`stated_units` and :func:`factor`; a column key for a joint the trial
        does not have.
    """
    stated = stated_units(meta, header_units, where, by=by)
    meta.pop("units", None)
    meta.pop("units_read", None)  # an earlier reader's record (the file is now in SI)
    if not stated:
        return
    record = {}
    for key, (unit, source) in stated.items():
        m = _COLUMN.match(key)
        signal, joint = m.group(1), m.group(2)
        if signal not in arrays or arrays[signal] is None:
            if source == "metadata 'units'" and signal in ("tau_delta", "tau_m",
                                                           "theta_ref"):
                continue  # an optional column the file does not have
            raise TrialFormatError(f"{where}: key 'units.{key}' names a column the trial "
                                   f"does not have")
        f = factor(key if joint or signal == "t" else f"{signal}[1]", unit, where)
        if f is None:
            continue
        if signal == "t":
            arrays["t"] = arrays["t"] * f
            record["t"] = {"unit": unit, "stated_by": source, "factor": f}
            continue
        arr = arrays[signal]
        cols = range(arr.shape[1]) if joint is None else [int(joint) - 1]
        if joint is not None and int(joint) > arr.shape[1]:
            raise TrialFormatError(f"{where}: key 'units.{key}' names joint {joint} of a "
                                   f"{arr.shape[1]}-joint trial")
        for j in cols:
            column = f"{signal}[{j + 1}]"
            if joint is None and column in stated:
                continue  # a column's own statement wins over its signal's
            arr[:, j] = arr[:, j] * f
            record[column] = {"unit": unit, "stated_by": source, "factor": f}
    if record:
        meta["units_read"] = record
