"""Numbers as a lab writes them (no numpy here: imported by the printed output too).

``plus_minus(value, ci)``: the interval half-width rounded to 2 significant digits and the
value rounded to the same decimal place (the usual rule for a measured value with its
uncertainty, e.g. BIPM JCGM 100:2008 "GUM" 7.2.6: "79.467 +- 1.599" is written
"79.5 ± 1.6").
"""

from __future__ import annotations

import math


def decimals_of(ci: float, sig: int = 2) -> int:
    """Decimal place (digits after the point; negative: tens, hundreds) at which ``ci``
    keeps ``sig`` significant digits once rounded (0.996 -> 1.0: 1, not 3).

    Raises ValueError for a ``ci`` that is zero, negative or not finite."""
    if not (math.isfinite(ci) and ci > 0):
        raise ValueError(f"an interval half-width must be positive and finite, got {ci!r}")
    d = sig - 1 - math.floor(math.log10(ci))
    if abs(round(ci, d)) >= 10.0 ** (sig - d):  # rounding carried into a new digit
        d -= 1
    return d


def at_decimals(x: float, d: int) -> str:
    """``x`` rounded to ``d`` decimals (``d`` < 0: to tens, hundreds), no "-0"."""
    text = f"{round(x, d):.{max(d, 0)}f}"
    return text[1:] if text.startswith("-") and float(text) == 0 else text


def round_pair(value: float, ci: float, sig: int = 2) -> tuple[str, str]:
    """``(value, ci)`` as texts: ``ci`` to ``sig`` significant digits, ``value`` to the
    same decimal place. A ``ci`` that is zero or not finite leaves no interval: the value
    with 4 significant digits and ``""`` for the interval."""
    if not (math.isfinite(ci) and ci > 0):
        return f"{value:.4g}", ""
    d = decimals_of(ci, sig)
    return at_decimals(value, d), at_decimals(ci, d)


def plus_minus(value: float, ci: float, unit: str = "", sig: int = 2) -> str:
    """``"79.5 ± 1.6 N m/rad"`` (see :func:`round_pair`); without an interval (``ci`` 0 or
    not finite) the value alone."""
    v, c = round_pair(value, ci, sig)
    text = f"{v} ± {c}" if c else v
    return f"{text} {unit}" if unit else text


def distinct(values, sig: int = 4, max_sig: int = 12) -> list[str]:
    """``values`` with ``sig`` significant digits (``:g``), or more, up to ``max_sig``,
    until values that differ print differently (1.2 and 1.20004: "1.2" and "1.20004",
    not "1.2" twice)."""
    values = [float(v) for v in values]
    for s in range(sig, max_sig + 1):
        texts = [f"{v:.{s}g}" for v in values]
        if all(texts[a] != texts[b] for a in range(len(values))
               for b in range(a) if values[a] != values[b]):
            return texts
    return texts
