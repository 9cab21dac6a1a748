"""How the numbers of a measured trial were stored, read from the numbers themselves.

A lab's trials are written by someone else's writer: a DAQ export at 6 significant digits,
``%.4f`` fixed decimals, MATLAB single precision, this project's ``%.17g``. The stored
value is the true sample rounded to the writer's representation, and that rounding is part
of the measurement: it adds white noise of variance step^2 / 12 per sample (Widrow's model
of uniform rounding) and it can hide or blur a sensor's quantisation grid.

:func:`detect_storage` finds the coarsest representation that reproduces every value of a
column exactly (significant digits, fixed decimals, float32, or float64 when none does).
The diagnosis then (1) stores every simulated column the same way before comparing it with
the measurement, so that measured and simulated numbers went through the same writer, and
(2) adds the rounding to the variance of every feature (features.py).
:func:`find_grid` reads a quantisation grid from stored samples, tolerating the storage
rounding, with the uncertainty of the step.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

EPS = np.finfo(float).eps
#: longest decimal representation tried; beyond 15 digits a double is "float64"
MAX_DIGITS = 15
#: a grid must be this many storage steps wide to be told from the storage rounding
GRID_RESOLVABLE_STEPS = 10.0


@dataclass(frozen=True)
class Storage:
    """The representation one column was stored in.

    Attributes
    ----------
    kind : {"float64", "float32", "significant", "decimals", "constant"}
        ``significant``: ``digits`` significant decimal digits (``%.{digits-1}e``);
        ``decimals``: ``digits`` digits after the decimal point (``%.{digits}f``);
        ``float32``: IEEE single precision (optionally printed with ``digits`` significant
        digits afterwards); ``constant``: every value is 0 or the column is constant.
    digits : int or None
    """

    kind: str
    digits: int | None = None

    def describe(self) -> str:
        if self.kind == "significant":
            return f"{self.digits} significant digits"
        if self.kind == "decimals":
            return f"{self.digits} decimals"
        if self.kind == "float32":
            return "float32" + (f" printed at {self.digits} significant digits"
                                if self.digits else "")
        return self.kind

    def step(self, x) -> np.ndarray:
        """Spacing of the representable values at each ``x`` [unit of x], shape of x."""
        x = np.asarray(x, dtype=float)
        if self.kind == "decimals":
            return np.full(x.shape, 10.0 ** -self.digits)
        if self.kind in ("significant", "float32") and self.digits:
            dec = _sig_step(x, self.digits)
            if self.kind == "significant":
                return dec
            return np.maximum(dec, np.abs(np.spacing(x.astype(np.float32))).astype(float))
        if self.kind == "float32":
            return np.abs(np.spacing(x.astype(np.float32))).astype(float)
        return np.abs(np.spacing(x))

    def max_error(self, x) -> np.ndarray:
        """Largest ``|stored - x|`` this representation makes at each ``x`` [unit of x],
        shape of x: half a step, and for float32 printed at ``digits`` digits the sum of
        both roundings (half the single-precision spacing, then half the printed step of
        the rounded value): t = 10.013 s is 10.0129995346 in float32 and 10.0129995
        after ``%.9g``, 5.0e-7 s from the truth, 2.3e-8 s beyond half the float32
        spacing (4.77e-7 s) that was the only tolerance before."""
        x = np.asarray(x, dtype=float)
        if self.kind == "float32" and self.digits:
            f32 = x.astype(np.float32)
            return 0.5 * (np.abs(np.spacing(f32)).astype(float)
                          + _sig_step(f32.astype(float), self.digits))
        return 0.5 * self.step(x)

    def apply(self, x) -> np.ndarray:
        """``x`` as this representation stores it (float64 array of the stored values)."""
        x = np.asarray(x, dtype=float)
        if self.kind == "float32":
            x = x.astype(np.float32).astype(float)
            return _round_sig(x, self.digits) if self.digits else x
        if self.kind == "significant":
            return _round_sig(x, self.digits)
        if self.kind == "decimals":
            return np.round(x, self.digits)
        return x.copy()

    def rounding_variance(self, x) -> float:
        """Mean variance step^2 / 12 of the rounding error over the samples ``x``
        [unit^2] (uniform rounding; Widrow & Kollar, Quantization Noise, 2008, ch. 4)."""
        s = self.step(x)
        return float(np.mean(s ** 2) / 12.0) if s.size else 0.0


def _sig_step(x, digits):
    ax = np.abs(x)
    with np.errstate(divide="ignore"):
        e = np.floor(np.log10(np.where(ax > 0, ax, 1.0)))
    return np.where(ax > 0, 10.0 ** (e - digits + 1), 0.0)


def _round_sig(x, digits):
    ax = np.abs(x)
    with np.errstate(divide="ignore"):
        e = np.floor(np.log10(np.where(ax > 0, ax, 1.0)))
    scale = 10.0 ** (digits - 1 - e)
    return np.where(ax > 0, np.rint(x * scale) / scale, 0.0)


def _is_integral(y) -> bool:
    """Every y within a few ulps of an integer. The tolerance is relative (16 ulps, at
    least those of 1): an absolute floor (1e-6, the first version) took every value
    below 1e-6 for the integer 0, so a column of angles of 1e-7 rad printed with 17
    digits was read as "0 decimals" and every simulated angle stored as 0."""
    tol = 16 * EPS * np.maximum(np.abs(y), 1.0)
    return bool(np.all(np.abs(y - np.rint(y)) <= tol))


def detect_storage(x) -> Storage:
    """The coarsest representation that reproduces every value of ``x`` exactly.

    Tries significant digits 1-15 and fixed decimals 0-15 (a value counts as
    representable when it is within a few float64 ulps of the decimal); of those that fit,
    the one with the larger mean log step. Else float32 when every value is a single-
    precision number; else float64. Decimal values that all lie within half a printed
    step of a float32 whose spacing is the coarser are float32 printed at those digits.

    Parameters
    ----------
    x : array_like
        One column (any shape; flattened).

    Returns
    -------
    Storage
    """
    x = np.asarray(x, dtype=float).ravel()
    nz = x[x != 0]
    if nz.size == 0 or np.ptp(x) == 0:
        return Storage("constant")
    with np.errstate(over="ignore", invalid="ignore"):  # 1e80 in float32, 10^300: no fit
        return _detect(x, nz)


def _detect(x, nz) -> Storage:
    ax = np.abs(nz)
    e = np.floor(np.log10(ax))
    fits = []
    for d in range(1, MAX_DIGITS + 1):
        y = ax * 10.0 ** (d - 1 - e)
        if 16 * EPS * y.max() < 0.01 and _is_integral(y):
            fits.append(Storage("significant", d))
            break
    top = ax.max()
    for n in range(0, MAX_DIGITS + 1):
        if 16 * EPS * top * 10.0 ** n >= 0.01:
            break
        if _is_integral(nz * 10.0 ** n):
            fits.append(Storage("decimals", n))
            break
    if fits:
        # the coarser one; on a tie fixed decimals (one uniform step explains it)
        best = max(fits, key=lambda s: (round(float(np.mean(np.log10(s.step(nz)))), 9),
                                        s.kind == "decimals"))
        # single-precision values printed with enough digits to tell them apart: every
        # value within half a printed step of a float32, whose spacing is the coarser
        f32 = nz.astype(np.float32).astype(float)
        spacing32 = np.abs(np.spacing(nz.astype(np.float32))).astype(float)
        printed = np.max([f.step(nz) for f in fits], axis=0)
        if np.all(np.abs(f32 - nz) <= 0.5 * printed + 4 * EPS * ax) and \
                np.median(spacing32) > np.median(best.step(nz)):
            sig = next((f.digits for f in fits if f.kind == "significant"), None)
            return Storage("float32", sig)
        return best
    if np.all(nz.astype(np.float32).astype(float) == nz):
        return Storage("float32")
    return Storage("float64")


@dataclass(frozen=True)
class Grid:
    """A quantisation grid read from stored samples.

    Attributes
    ----------
    step : float
        Grid step [unit of the samples]; 0 when no grid was found.
    sigma : float
        Standard uncertainty of ``step`` from the storage rounding [same unit].
    resolvable : float
        Smallest step this storage could reveal (``GRID_RESOLVABLE_STEPS`` storage steps
        of the largest sample) [same unit].
    """

    step: float
    sigma: float
    resolvable: float

    def to_dict(self) -> dict:
        return {"step": self.step, "sigma": self.sigma, "resolvable": self.resolvable}


def resolvable_step(x, storage: Storage) -> float:
    """Smallest grid step that ``storage`` can reveal in samples like ``x``."""
    x = np.asarray(x, dtype=float)
    if x.size == 0:
        return 0.0
    return float(GRID_RESOLVABLE_STEPS * storage.step(np.array([np.abs(x).max()]))[0])


def find_grid(x, storage: Storage | None = None, *, resolvable: float | None = None) -> Grid:
    """Quantisation step of the stored samples ``x``, tolerant of the storage rounding.

    The distinct stored values of a quantised signal ``r * round(x / r)`` (plus any offset)
    differ by integer multiples k r, each difference off by at most the two values'
    rounding (half a storage step each). The step is the smallest difference, refined by
    least squares over all differences (sum k du / sum k^2); the samples are on that grid
    when every difference is within its rounding of k r. The grid must be at least
    ``resolvable`` wide (default: ``GRID_RESOLVABLE_STEPS`` storage steps), else the
    storage, not the sensor, made the steps.

    Parameters
    ----------
    x : ndarray (N,)
    storage : Storage, optional
        Default: detected from ``x``.
    resolvable : float, optional
        Smallest step accepted; pass the measured trial's value when reading a simulated
        trial stored the same way, so both are judged alike.

    Returns
    -------
    Grid
    """
    x = np.asarray(x, dtype=float)
    storage = storage or detect_storage(x)
    limit = resolvable_step(x, storage) if resolvable is None else float(resolvable)
    none = Grid(0.0, 0.0, limit)
    u = np.unique(x)
    if u.size < 3:
        return none
    du = np.diff(u)
    grid = _tolerant_grid(u, du, storage, limit)
    if grid is None:
        decimal = _decimal_grid(u, du, storage)
        grid = None if decimal is None else Grid(decimal, 0.0, limit)
    return none if grid is None else grid


def _tolerant_grid(u, du, storage: Storage, limit: float) -> Grid | None:
    """The grid of the distinct stored values ``u`` read within their rounding."""
    if not du.min() > 0 or du.min() < limit:
        return None
    half = np.maximum(storage.max_error(u), 4 * EPS * np.abs(u).max())
    var_du = (half[:-1] ** 2 + half[1:] ** 2) / 3.0  # two uniform roundings
    # first guess: the most precisely stored of the smallest differences
    small = du <= 1.5 * du.min()
    r = float(du[small][np.argmin(var_du[small])])
    w = 1.0 / var_du
    for _ in range(3):  # weighted least squares over all differences, du = k r
        k = np.rint(du / r)
        if k.max() > 1e7 or np.any(k < 1):
            return None
        r = float(np.sum(w * k * du) / np.sum(w * k * k))
    k = np.rint(du / r)
    sigma = float(1.0 / math.sqrt(np.sum(w * k * k)))
    # each difference: its two roundings, plus k times the uncertainty of the fitted step
    tol = (1.01 * (half[:-1] + half[1:]) + 5.0 * k * sigma
           + 16 * EPS * np.maximum(np.abs(u[:-1]), np.abs(u[1:])))
    if np.any(k < 1) or np.any(np.abs(du - k * r) > tol):
        return None
    return Grid(r, sigma, limit)


def _decimal_grid(u, du, storage: Storage) -> float | None:
    """A grid that is itself a multiple of a decimal storage step (e.g. 0.005 N m stored
    with 3 decimals, or written bit-exact but decimal-valued): every difference is an
    integer number m of the finest storage step, and the samples lie on a grid when the
    greatest common divisor of the m is 2 or more (5 with fewer than 20 distinct values;
    unquantised samples give 1). Tried
    only when the grid is too fine for :func:`_tolerant_grid`."""
    if storage.kind != "decimals":  # a uniform step: multi-scale steps share factors
        return None
    steps = storage.step(u)
    unit = steps[steps > 0].min() if np.any(steps > 0) else 0.0
    if not unit > 0 or du.max() / unit > 1e15:
        return None
    m = np.rint(du / unit)
    if np.any(np.abs(du - m * unit) > 0.01 * unit + 16 * EPS * np.abs(u[1:])):
        return None
    g = int(np.gcd.reduce(m.astype(np.int64)))
    # among a few rounded differences a common factor of 2-4 arises by chance; among 20
    # or more distinct values it does not (probability 2^-19)
    return float(g * unit) if g >= 5 or (g >= 2 and u.size >= 20) else None
