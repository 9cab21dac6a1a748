"""What every bench does at its end: write its figures to ``bench/results/NAME.json``
atomically (a temporary file in the same folder, then one rename), so that an interrupted
bench never leaves a cut results file, and say where they went.

Standard library only: a bench must not change what it measures by importing the project.
"""

from __future__ import annotations

import json
import math
import os
import tempfile
from pathlib import Path

#: where the benches' results go
RESULTS = Path(__file__).resolve().parent / "results"


def write_results(name: str, doc, *, indent: int = 1) -> Path:
    """Write ``doc`` as ``bench/results/NAME.json`` atomically; print and return the path.

    ``doc`` is any JSON-serialisable value; numpy scalars are written as floats
    (``default=float``).
    """
    RESULTS.mkdir(parents=True, exist_ok=True)
    out = RESULTS / f"{name}.json"
    fd, tmp = tempfile.mkstemp(dir=RESULTS, prefix=f".{name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as fh:
            json.dump(doc, fh, indent=indent, default=float)
            fh.write("\n")
        os.replace(tmp, out)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    print(f"wrote bench/results/{out.name}")
    return out


def wilson(k: int, n: int, z: float = 1.96):
    """95 % Wilson score interval of k successes in n (Wilson 1927)."""
    if n == 0:
        return [0.0, 1.0]
    p = k / n
    c = (p + z * z / (2 * n)) / (1 + z * z / n)
    h = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    return [max(0.0, c - h), min(1.0, c + h)]


def write_blind(rec, folder: Path, name: str, representation: str) -> Path:
    """Write labsim recording ``rec`` into ``folder / name`` in ``representation`` with
    its truth files moved beside that folder (``name.*truth*``), so that a diagnosis of
    the folder never sees the truth. Returns the folder to read."""
    import labsim
    sub = Path(folder) / name
    sub.mkdir(parents=True, exist_ok=True)
    labsim.write(rec, sub, "rec_0000", representation, truth_fs=None)
    for p in sub.glob("*truth*"):  # blind: the diagnosis never sees the truth
        p.rename(Path(folder) / f"{sub.name}.{p.name}")
    return sub
