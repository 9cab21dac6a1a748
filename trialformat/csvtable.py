"""CSV tables of any common writer, parsed by pyarrow (docs/spec/log-format.md, "Lab data").

Accepted as RFC 4180 defines CSV: quoted header names and fields, CRLF or LF line ends, a
UTF-8 byte-order mark, ``,`` ``;`` or tab as the field separator (``.`` decimal mark), and
extra columns of any content (text, blank or NaN cells), which are returned only when
numeric; their text may be in any encoding (Latin-1, cp1252: never decoded). A file in
UTF-16 or UTF-32 (byte-order mark, or NUL-interleaved header) is refused naming the
encoding ("save it as UTF-8"). The fast
path is one ``pyarrow.csv.read_csv`` call; when it fails, the file is
re-read with the standard ``csv`` module only to name the 1-based data row and the column
at fault.
"""

from __future__ import annotations

import csv
import gzip
import io
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.csv as pacsv

from .errors import TrialFormatError

DELIMITERS = (",", ";", "\t")


#: Longest header line read [characters]: a file whose first line is longer (a binary
#: file, or no newline at all) is refused instead of read whole into memory.
MAX_HEADER_CHARS = 1 << 20


def open_text(path: Path):
    """The file as text (UTF-8, BOM removed, undecodable bytes replaced), gunzipped when
    its name ends in ``.gz``."""
    if str(path).lower().endswith(".gz"):
        return gzip.open(path, "rt", encoding="utf-8-sig", errors="replace", newline="")
    return open(path, encoding="utf-8-sig", errors="replace", newline="")


def printable(text: str, *, lines: bool = False) -> str:
    """``text`` with control and other non-printable characters escaped (``\\x1b``,
    ``\\u200b``), so a binary or escape-sequence header is never echoed raw to a
    terminal. ``lines=True`` keeps line breaks (a message of several problems, one per
    line), escaping the rest of each line."""
    if lines:
        return "\n".join(printable(part) for part in text.split("\n"))
    return "".join(c if c.isprintable() else c.encode("unicode_escape").decode("ascii")
                   for c in text)


#: Byte-order marks of the encodings a CSV trial cannot be in (longest first: UTF-32 LE
#: starts with UTF-16 LE's mark).
WIDE_BOMS = ((b"\xff\xfe\x00\x00", "UTF-32"), (b"\x00\x00\xfe\xff", "UTF-32"),
             (b"\xff\xfe", "UTF-16"), (b"\xfe\xff", "UTF-16"))


def _refuse_wide_encoding(path: Path) -> None:
    """Refuse a file in UTF-16 or UTF-32 (a byte-order mark, or NUL bytes making more than
    30 % of its first line: NUL-interleaved ASCII, 50 % in UTF-16 and 75 % in UTF-32),
    naming the encoding and the fix (save as UTF-8)."""
    try:
        opener = gzip.open if str(path).lower().endswith(".gz") else open
        with opener(path, "rb") as fh:
            head = fh.read(4096)
    except (OSError, EOFError):
        return  # read_header says what is wrong
    match = next(((bom, name) for bom, name in WIDE_BOMS if head.startswith(bom)), None)
    if match is not None:
        found, why = match[1], "byte-order mark " + " ".join(f"{c:02X}" for c in match[0])
    else:
        line = head.split(b"\n", 1)[0]
        zeros = line.count(b"\x00") / max(len(line), 1)
        if zeros <= 0.3:  # none, or a stray NUL: the header check names the columns
            return
        found = "UTF-32" if zeros > 0.6 else "UTF-16"
        why = "NUL bytes between the header's characters"
    raise TrialFormatError(f"{path}: looks {found} encoded ({why}); save it as UTF-8 "
                           f"(e.g. Excel: 'CSV UTF-8'; iconv -f {found} -t UTF-8)")


def read_header(path: Path) -> tuple[list[str], str]:
    """Header names (quotes, BOM and surrounding blanks removed) and the field separator.

    The separator is the candidate giving the most header fields. At most
    :data:`MAX_HEADER_CHARS` characters are read: a longer first line is refused.

    Raises
    ------
    TrialFormatError
        Empty file, a first line longer than :data:`MAX_HEADER_CHARS`, or a file that is
        not gzip although its name ends in ``.gz``.
    """
    _refuse_wide_encoding(path)
    # undecodable bytes can only be in extra names (declared ones are ASCII): replaced
    try:
        with open_text(path) as fh:
            first = fh.readline(MAX_HEADER_CHARS + 1)
    except (OSError, EOFError) as exc:  # gzip.BadGzipFile is an OSError
        raise TrialFormatError(f"{path}: not readable as "
                               f"{'gzip' if str(path).lower().endswith('.gz') else 'text'}: "
                               f"{exc}") from None
    if len(first) > MAX_HEADER_CHARS:
        raise TrialFormatError(f"{path}: first line (the header) is longer than "
                               f"{MAX_HEADER_CHARS} characters with no line end: not a CSV "
                               f"trial (one header line, then one row per sample)")
    if not first.strip():
        raise TrialFormatError(f"{path}: file is empty (no header row)")
    try:
        best = max(DELIMITERS, key=lambda d: len(next(csv.reader([first], delimiter=d))))
        header = [h.strip() for h in next(csv.reader([first], delimiter=best))]
    except csv.Error as exc:
        raise TrialFormatError(f"{path}: header row does not parse as CSV: {exc}") from None
    return header, best


def read_columns(path: Path, header: list[str], delimiter: str,
                 numeric: list[str]) -> tuple[dict, dict]:
    """Parse the data rows; return ``(declared, extra)`` dicts of float64 arrays.

    ``numeric`` names the declared columns, which must parse as numbers in every row
    (blank, NaN and infinite cells come back as NaN/inf for the caller's finiteness
    check). Extra columns are returned when pyarrow reads them as numbers, else dropped.

    Raises
    ------
    TrialFormatError
        A row with the wrong number of fields or a non-numeric declared cell, naming the
        file, the 1-based data row and the column.
    """
    keys = [f"c{i}" for i in range(len(header))]
    index = {name: i for i, name in enumerate(header)}
    types = {keys[index[name]]: pa.float64() for name in numeric}
    try:
        table = pacsv.read_csv(
            path,
            read_options=pacsv.ReadOptions(column_names=keys, skip_rows=1, use_threads=False),
            parse_options=pacsv.ParseOptions(delimiter=delimiter),
            convert_options=pacsv.ConvertOptions(column_types=types, strings_can_be_null=True,
                                                 check_utf8=False))
    except pa.ArrowInvalid as exc:
        if "Empty CSV file" in str(exc):
            return {name: np.empty(0) for name in numeric}, {}
        _locate_error(path, header, delimiter, numeric, exc)
    except OSError as exc:  # pyarrow's decompression: a damaged or cut .gz
        raise TrialFormatError(f"{path}: cannot be read ({exc}); a .gz trial must be one "
                               f"whole gzip stream: recompress it") from None
    declared = {name: _as_float(table.column(keys[index[name]])) for name in numeric}
    extra = {}
    for name, key in zip(header, keys):
        if name in declared or name in extra:
            continue
        col = table.column(key)
        if pa.types.is_integer(col.type) or pa.types.is_floating(col.type):
            extra[name] = _as_float(col)
    return declared, extra


def _as_float(column) -> np.ndarray:
    """float64 copy of a pyarrow column, nulls (blank cells) as NaN.

    Read from the Arrow buffers directly: pyarrow's own ``to_numpy`` imports pandas
    (0.3 s per process) for columns with nulls.
    """
    parts = []
    for chunk in column.chunks:
        if not pa.types.is_float64(chunk.type):
            chunk = chunk.cast(pa.float64())
        data = np.frombuffer(chunk.buffers()[1], dtype=np.float64, count=len(chunk),
                             offset=chunk.offset * 8).copy()
        if chunk.null_count:
            valid = np.unpackbits(np.frombuffer(chunk.buffers()[0], dtype=np.uint8),
                                  bitorder="little")[chunk.offset:chunk.offset + len(chunk)]
            data[valid == 0] = np.nan
        parts.append(data)
    return np.concatenate(parts) if parts else np.empty(0)


def _locate_error(path, header, delimiter, numeric, exc) -> None:
    """Find the first bad row/cell with the csv module and raise naming it."""
    wanted = {header.index(name): name for name in numeric}
    with open_text(path) as fh:
        reader = csv.reader(fh, delimiter=delimiter)
        next(reader)
        rows = (row for row in reader if row)  # blank lines: skipped, as pyarrow does
        for row_no, row in enumerate(rows, start=1):
            if len(row) != len(header):
                cut = ""
                if len(row) < len(header) and next(rows, None) is None:
                    cut = (": it is the last row, so the file looks cut short (a recording "
                           "or export stopped mid-row); delete that row, or export the "
                           "file again")
                raise TrialFormatError(f"{path}: data row {row_no} has {len(row)} fields, the "
                                       f"header has {len(header)}{cut}") from None
            for i, name in wanted.items():
                cell = row[i].strip()
                if cell.lower() in ("", "nan", "na", "n/a", "null"):
                    continue  # reported as non-finite by the caller
                try:
                    float(cell)
                except ValueError:
                    hint = (" (a decimal comma? write '.' as the decimal mark)"
                            if "," in cell and delimiter != "," else "")
                    raise TrialFormatError(f"{path}: non-numeric value {printable(repr(cell))} in column "
                                           f"'{name}' at data row {row_no}{hint}") from None
    raise TrialFormatError(f"{path}: CSV does not parse: {exc}") from None


def to_text(header: list[str], table: np.ndarray) -> bytes:
    """The project's own writing: plain CSV, ``,`` separator, unquoted header.

    Values in the shortest text that reads back to the same double (pyarrow's writer),
    so a trial read back is bit-identical; about 4x faster than ``%.17g`` formatting.
    """
    columns = {f"c{i}": np.ascontiguousarray(table[:, i], dtype=float)
               for i in range(table.shape[1])}
    buf = io.BytesIO()
    pacsv.write_csv(pa.table(columns), buf,
                    write_options=pacsv.WriteOptions(include_header=False,
                                                     quoting_style="none"))
    return (",".join(header) + "\n").encode() + buf.getvalue()
