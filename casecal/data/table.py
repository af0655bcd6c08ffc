"""A CSV file as a table of numbers, read in chunks so the file, not the parser, bounds
the memory (`read_table`, used by `casecal.data.files.read_csv`)."""

from __future__ import annotations

import codecs
import csv
import io
import os
import re
import warnings
from pathlib import Path

import numpy as np
import pandas as pd

from ..errors import CalibrationError
from ..textio import read_bytes

TEXT_COLUMNS = ("session",)
"""Columns read as text whatever they hold: labels, where ``1`` and ``1.0`` differ."""

CHUNK_ROWS = 20_000
"""Rows parsed at a time: each chunk's columns become numbers before the next is read."""

READ_COST = 3
"""Memory to read a file, in multiples of its size (measured: 1.5 at 1e6 rows of puma560,
1.7 at 1e5: the parser's buffers count more in a small file)."""


def read_table(path, what: str = "measurement file") -> tuple[pd.DataFrame, str]:
    """A CSV file as a DataFrame, checked: it exists, parses, has unique columns and at
    least one row. Returns the frame and the label for messages.

    Columns whose every value is a number are float64 or int64 (parsed once, exactly as
    Python's ``float`` does); others hold strings, which `casecal.data.files` refuses with
    the row and value where a number is needed. Reading costs about the file's size in
    memory, at most `READ_COST` times it; a file too large for the memory at hand is one
    error saying how many rows would fit.

    `path` may be ``"-"`` (standard input), a pipe or a process substitution. Commas
    separate the columns; a file whose header is split by tabs or semicolons instead is
    read with that separator. The text must be UTF-8 (with or without a byte-order mark);
    UTF-16 is refused by name. A line starting with ``#`` is refused with its line number,
    not skipped: CSV has no comments, and skipping lines would shift the row numbers that
    every message (and the outlier notes) give.
    """
    label = "standard input" if str(path) == "-" else str(path)
    try:
        data = read_bytes(path, what)
        _check_text(data, label, what)
        first = data[:65536].split(b"\n", 1)[0]
        sep = next((d for d in ("\t", ";") if d.encode() in first and b"," not in first), ",")
        _check_rows(data, sep, label)
        chunks = _chunks(data, sep, label)
        del data  # the text goes before the chunks are joined: the peak is one of them
        df = pd.concat(chunks, ignore_index=True) if len(chunks) > 1 else chunks[0]
        del chunks
    except MemoryError:
        df = None  # measured below, once the failed attempt's memory is free
    if df is None:
        raise CalibrationError(too_big(path, label))
    columns = [str(c).strip() for c in df.columns]
    duplicated = sorted({c for c in columns if columns.count(c) > 1} | _mangled(columns))
    if duplicated:
        raise CalibrationError(f"{label}: column {duplicated[0]!r} appears twice; keep one")
    df.columns = columns
    if df.empty:
        raise CalibrationError(f"{label}: the header has no rows below it; add one row per pose")
    return df, label


def _check_text(data: bytes, label: str, what: str) -> None:
    """Refuse UTF-16 (whose ASCII letters are valid UTF-8 between NUL bytes, so it parsed
    as one garbled column), other binary or non-UTF-8 files, and ``#`` lines."""
    head = data[:4096]
    if head.startswith((codecs.BOM_UTF16_LE, codecs.BOM_UTF16_BE)) or (
        b"\x00" in head and max(head[0::2].count(0), head[1::2].count(0)) > len(head) // 4
    ):
        raise CalibrationError(
            f"{label}: the file is UTF-16 text; save it as UTF-8 (in Excel: CSV UTF-8; "
            "or iconv -f UTF-16 -t UTF-8)"
        )
    if b"\x00" in data:
        raise CalibrationError(f"{label}: the file holds NUL bytes: it is not a text {what}")
    decoder = codecs.getincrementaldecoder("utf-8")()
    view = memoryview(data)
    try:
        for start in range(0, len(data), 1 << 20):  # validate without a str of the whole file
            decoder.decode(view[start : start + (1 << 20)])
        decoder.decode(b"", final=True)
    except UnicodeDecodeError:
        raise CalibrationError(f"{label}: the {what} is not UTF-8 text; save it as UTF-8") from None
    finally:
        view.release()
    if data.startswith((b"#", codecs.BOM_UTF8 + b"#")):
        line = 1
    else:
        at = data.find(b"\n#")
        line = data.count(b"\n", 0, at + 1) + 1 if at >= 0 else 0
    if line:
        name = "FILE" if label == "standard input" else label
        raise CalibrationError(
            f"{label}: line {line} starts with '#': CSV files have no comments; delete the "
            f"comment lines (e.g. grep -v '^#' {name} > clean.csv)"
        )


def _chunks(data: bytes, sep: str, label: str) -> list[pd.DataFrame]:
    """`data` parsed `CHUNK_ROWS` rows at a time, each column typed as it is read."""
    try:
        with warnings.catch_warnings():
            # a row with more fields than the header must fail, not lose or shift data
            warnings.simplefilter("error", pd.errors.ParserWarning)
            reader = pd.read_csv(
                io.BytesIO(data),  # shares the bytes, no copy
                sep=sep,
                encoding="utf-8",
                na_filter=False,  # an empty or 'NA' field is text, refused where a number goes
                skipinitialspace=True,
                index_col=False,
                chunksize=CHUNK_ROWS,
                dtype=dict.fromkeys(TEXT_COLUMNS, str),
            )
            with reader:
                return list(reader)
    except pd.errors.ParserWarning:
        # `_check_rows` finds these first; this is the parser's word if it counts otherwise
        raise CalibrationError(
            f"{label}: some rows have more fields than the header; check the delimiters "
            "and that every value has a column name"
        ) from None
    except pd.errors.EmptyDataError:
        raise CalibrationError(
            f"{label}: the file is empty; it needs a header and one row per pose"
        ) from None
    except (pd.errors.ParserError, ValueError) as exc:
        if "out of memory" in str(exc):  # the C tokenizer's MemoryError
            raise MemoryError from None
        if "on source failed" in str(exc):
            # pandas turns a Ctrl-C that lands in its read of these in-memory bytes (which
            # cannot fail otherwise) into this error: it is an interrupt, not a bad file
            raise KeyboardInterrupt from None
        counted = re.search(r"Expected (\d+) fields in line (\d+), saw (\d+)", str(exc))
        if counted:  # the parser's line counts blank lines and the header: the file's line
            header, line, fields = map(int, counted.groups())
            raise CalibrationError(_uneven_message(label, sep, line, fields, header)) from None
        detail = " ".join(str(exc).split())  # pandas' messages span lines
        raise CalibrationError(f"{label}: not a readable CSV file ({detail})") from None


def _check_rows(data: bytes, sep: str, label: str) -> None:
    """Refuse a row whose field count is not the header's, and a blank line with rows after
    it, naming the file's line.

    The parser refuses a long row with a message of its own, but fills a short one with
    empty fields: a value missing in the middle shifts the rest one column left, silently
    into the wrong columns if the last column is not one casecal reads. It skips blank
    lines, which would shift every row number a message (and the outlier notes) give.
    """
    found = _uneven_quoted(data, sep) if b'"' in data else _uneven(data, sep)
    if found is None:
        return
    line, fields, header = found
    if fields == 0:
        name = "FILE" if label == "standard input" else label
        raise CalibrationError(
            f"{label}: line {line} is blank; delete the blank lines (e.g. grep -v "
            f"'^[[:space:]]*$' {name} > clean.csv): messages number the rows by their line"
        )
    raise CalibrationError(_uneven_message(label, sep, line, fields, header))


def _uneven_message(label: str, sep: str, line: int, fields: int, header: int) -> str:
    what = {",": "comma", ";": "semicolon", "\t": "tab"}[sep]
    if fields > header:
        comma = " (a comma inside a number, e.g. 1,5 for 1.5?)" if sep == "," else ""
        return (
            f"{label}: line {line} has {fields} fields, the header {header}: check the "
            f"delimiters{comma} and that every value has a column name"
        )
    return (
        f"{label}: line {line} has {fields} fields, the header {header}: the row is short "
        f"(a value or a {what} is missing); give it one value per column"
    )


WINDOW = 1 << 22
"""Bytes whose lines `_uneven` counts at a time: its arrays stay a few times this."""


def _uneven(data: bytes, sep: str) -> tuple[int, int, int] | None:
    """The first line whose field count differs from the header's, as (line, fields,
    header fields), fields 0 for a blank line with rows after it; or None.

    For text without quotes, where a field count is one more than the separators: counted
    with numpy a window of whole lines at a time, as fast as reading.
    """
    end = data.find(b"\n")
    end = len(data) if end < 0 else end
    if not data[:end].strip():  # the parser would take a later line for the header
        return (1, 0, 0) if data[end:].strip() else None
    header = data.count(sep.encode(), 0, end)
    everything = np.frombuffer(data, np.uint8)
    blank, done, pos = None, 0, 0  # done: lines before pos
    while pos < len(data):
        stop = min(pos + WINDOW, len(data))
        if stop < len(data):
            cut = data.rfind(b"\n", pos, stop)
            stop = cut + 1 if cut >= 0 else data.find(b"\n", stop) + 1 or len(data)
        window = everything[pos:stop]
        ends = np.flatnonzero(window == 10)
        if not len(ends) or ends[-1] != len(window) - 1:
            ends = np.append(ends, len(window))  # the last line, without its newline
        starts = np.concatenate(([0], ends[:-1] + 1))
        seps = np.flatnonzero(window == ord(sep))
        counts = np.diff(np.searchsorted(seps, ends), prepend=0)
        odd = np.flatnonzero((counts != header) | (ends - starts <= 1))
        is_blank = np.zeros(len(ends), bool)
        for i in odd:
            if not bytes(window[starts[i] : ends[i]]).strip():
                is_blank[i] = True
                blank = blank or done + i + 1
            elif blank:
                return blank, 0, header + 1
            elif counts[i] != header:
                return done + i + 1, int(counts[i]) + 1, header + 1
        if blank and not is_blank[max(blank - done - 1, 0) :].all():
            return blank, 0, header + 1
        done, pos = done + len(ends), stop
    return None


def _uneven_quoted(data: bytes, sep: str) -> tuple[int, int, int] | None:
    """`_uneven` for text with quotes, whose fields may hold separators and newlines: read
    as the parser does, by Python's csv module (slower, and rare in measurement files)."""
    text = io.TextIOWrapper(io.BytesIO(data), encoding="utf-8-sig", newline="")
    reader = csv.reader(text, delimiter=sep, skipinitialspace=True)
    header, blank, line = None, None, 1
    try:
        for row in reader:
            empty = len(row) <= 1 and not "".join(row).strip()
            if empty:
                blank = blank or line
            elif blank:
                return blank, 0, header or 0
            elif header is None:
                header = len(row)
            elif len(row) != header:
                return line, len(row), header
            line = reader.line_num + 1
    except csv.Error:
        return None  # the parser says what it makes of it
    return None


def too_big(path, label: str) -> str:
    """The message for a file that does not fit in memory: its size and what would fit."""
    size, per_row = 0, 0.0
    try:
        if str(path) != "-":  # standard input is gone once read
            size = os.stat(path).st_size
            with open(path, "rb") as fh:
                head = fh.read(1 << 16)
            per_row = len(head) / max(head.count(b"\n"), 1)
    except OSError:
        pass
    free = _free_memory()
    rows = ""
    fit = int(free / (READ_COST * per_row)) // 1000 * 1000 if free and per_row else 0
    if fit:
        rows = f"; about {fit:,} rows would fit (e.g. head -n {fit + 1} {label} > part.csv)"
    what = f"{size / 1e6:,.0f} MB, " if size else ""
    return (
        f"{label}: not enough memory to read the file ({what}reading takes up to "
        f"{READ_COST}x its size){rows}; split it or use a machine with more memory"
    )


def _free_memory() -> float | None:
    """Bytes this process could still get (Linux: available memory and its address-space
    limit), or None where that is unknown."""
    free = []
    try:
        text = Path("/proc/meminfo").read_text()
        free.append(float(re.search(r"MemAvailable:\s+(\d+)", text).group(1)) * 1024)
    except (OSError, AttributeError):
        pass
    try:
        import resource

        limit = resource.getrlimit(resource.RLIMIT_AS)[0]
        if limit != resource.RLIM_INFINITY:
            used = int(Path("/proc/self/statm").read_text().split()[0]) * os.sysconf("SC_PAGE_SIZE")
            free.append(max(limit - used, 0))
    except (ImportError, OSError, ValueError, IndexError):
        pass
    return min(free) if free else None


def _mangled(columns) -> set[str]:
    # pandas renames a repeated header 'x' to 'x.1'
    return {
        c.rsplit(".", 1)[0]
        for c in columns
        if re.search(r"\.\d+$", c) and c.rsplit(".", 1)[0] in columns
    }
