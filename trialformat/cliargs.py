"""Argument types for the command lines (``armimp`` subcommands): numbers checked at
parse time, so a value out of range is refused in one line naming the option and a value
that works (``--duration inf``, ``--fs 1e9``, ``--rk4-step 0``, ``--nfft 1e8``).

The limits are far above any experiment of this project yet below what exhausts memory or
time: a trial of at most :data:`MAX_SAMPLES` samples, a Welch segment or FFT of at most
:data:`MAX_FFT` samples.
"""

from __future__ import annotations

import argparse
import math
import re

#: Longest trial [samples] a command simulates (10 000 s at 1 kHz).
MAX_SAMPLES = 10_000_000
#: Longest Welch segment / FFT [samples] (2**22, 70 min at 1 kHz).
MAX_FFT = 1 << 22


def number(option: str, lo: float, hi: float, example, *, integer: bool = False,
           lo_open: bool = True, unit: str = ""):
    """An argparse ``type``: a finite number in ``(lo, hi]`` (``[lo, hi]`` when not
    ``lo_open``), an integer when ``integer``; the error names ``option``, the range and
    ``example``."""
    left = "(" if lo_open else "["
    what = "an integer" if integer else "a finite number"
    unit_text = f" {unit}" if unit else ""

    def parse(text: str):
        try:
            value = float(text)
            if integer:
                if not math.isfinite(value) or value != int(value):
                    raise ValueError
                value = int(value)
        except (TypeError, ValueError, OverflowError):
            value = None
        ok = value is not None and math.isfinite(value) and value <= hi and (
            value > lo if lo_open else value >= lo)
        if not ok:
            bounds = f"{left}{lo:g}, {int(hi) if integer else format(hi, 'g')}]"
            # argparse prefixes "argument OPTION: "
            raise argparse.ArgumentTypeError(f"must be {what} in {bounds}{unit_text}, got "
                                             f"{text!r} (e.g. {option} {example})")
        return value

    parse.__name__ = option.lstrip("-").replace("-", "_")
    return parse


def check_samples(duration_s: float, fs: float, *, option: str = "--duration") -> None:
    """Refuse a trial longer than :data:`MAX_SAMPLES` samples, naming ``option`` and the
    longest duration that works at ``fs``.

    Raises
    ------
    ValueError
    """
    if duration_s * fs > MAX_SAMPLES:
        raise ValueError(f"{option} {duration_s:g} s at {fs:g} Hz is {duration_s * fs:.3g} "
                         f"samples, above the limit of {MAX_SAMPLES} (give {option} <= "
                         f"{MAX_SAMPLES / fs:g})")


_NAMED = re.compile(r"^(?P<file>[^\n:]+?):(?P<name>[^\n:]+): (?P<text>.*)$", re.S)


def reader_notes(caught) -> list:
    """The lines a command prints for the warnings its readers gave (``warnings.
    catch_warnings(record=True)``): libraries' deprecation notices to their own callers
    (mat-io on pandas) dropped; one note per file for the same note on several of its
    recordings (``FILE.mat:z_df: ...``, ``FILE.mat:z_pf: ...`` become ``FILE.mat (z_df,
    z_pf): ...``); one note, with the count, for the same note on several files;
    control characters escaped."""
    from .csvtable import printable

    texts = [str(w.message) for w in caught
             if not issubclass(w.category, (DeprecationWarning, FutureWarning))]
    return [f"note: {printable(line, lines=True)}" for line in merged_notes(texts)]


_FILE_NOTE = re.compile(r"^(?P<file>[^\n:]+?): (?P<text>.*)$", re.S)


def merged_notes(texts) -> list:
    """Notes (``"FILE:VAR: text"``, ``"FILE: text"``, plain) with repeats merged, in first
    order: a text said for several variables of one file once per file, a text said for
    several files once with their count and the first names."""
    per_file: dict = {}
    for text in texts:
        m = _NAMED.match(text)
        key = (m["file"], m["text"]) if m else (None, text)
        per_file.setdefault(key, []).append(m["name"] if m else None)
    lines = []
    for (file, text), names in per_file.items():
        if file is None:
            lines.append(text)
        elif len(names) == 1:
            lines.append(f"{file}:{names[0]}: {text}")
        else:
            lines.append(f"{file} ({', '.join(names)}): {text}")
    per_text: dict = {}
    for line in lines:
        m = _FILE_NOTE.match(line)
        key = m["text"] if m and " " not in m["file"].strip("()") else line
        per_text.setdefault(key, []).append(m["file"] if key != line else None)
    out = []
    for text, files in per_text.items():
        if len(files) < 3 or None in files:
            out += [f"{f}: {text}" if f else text for f in files]
        else:
            shown = ", ".join(files[:3]) + (", ..." if len(files) > 3 else "")
            out.append(f"{len(files)} files ({shown}): {text}")
    return list(dict.fromkeys(out))
