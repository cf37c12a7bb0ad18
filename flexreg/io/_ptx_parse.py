"""The PTX text parser: a parallel numba kernel over the raw bytes of whole lines
(:func:`parse_all`), used by :mod:`flexreg.io.ptx`, which validates what it returns."""

from __future__ import annotations

import numba
import numpy as np
from numba import prange
from numpy.typing import NDArray

_MAX_VALUES = 7
POW10 = np.array([10.0**i for i in range(23)])

# error codes of the line parser
_OK, _BAD_NUMBER, TOO_MANY = 0, 1, 2


# ------------------------------------------------------------------------------ parsing kernels


@numba.njit(cache=True, nogil=True, inline="always")
def _is_space(b: np.uint8) -> bool:
    return b == 32 or b == 9 or b == 13 or b == 10


@numba.njit(cache=True, nogil=True, inline="always")
def _line_end(buf: NDArray[np.uint8], i: int, n: int) -> int:
    """Index of the first ``\\n`` of ``buf[i:n]``, ``n`` when there is none."""
    while i < n and buf[i] != 10:
        i += 1
    return i


@numba.njit(cache=True, nogil=True)
def _parse_line(
    buf: NDArray[np.uint8], lo: int, n: int, out: NDArray[np.float64], pow10: NDArray[np.float64]
) -> tuple[int, int, int]:
    """Parse the whitespace-separated decimal numbers of the line starting at ``buf[lo]`` (up
    to its ``\\n`` or ``n``) into ``out``, in the same pass that finds the line's end.

    Returns ``(count, error, end)``, ``end`` the index of the line's ``\\n`` (or ``n``).
    Numbers: optional sign, digits, optional fraction, optional exponent. Up to 18 significant
    digits are exact; with at most 15 digits and a decimal exponent within +-22 the result is
    correctly rounded (exact integer / exact power of ten).
    """
    i = lo
    count = 0
    while True:
        while i < n and (buf[i] == 32 or buf[i] == 9 or buf[i] == 13):
            i += 1
        if i >= n or buf[i] == 10:
            return count, _OK, i
        if count >= out.shape[0]:
            return count, TOO_MANY, _line_end(buf, i, n)
        neg = False
        if buf[i] == 45 or buf[i] == 43:  # - +
            neg = buf[i] == 45
            i += 1
        mant = 0
        exp10 = 0
        ndig = 0  # significant digits kept in mant
        digits = 0  # digits seen at all
        while i < n and 48 <= buf[i] <= 57:
            if ndig < 18:
                mant = mant * 10 + (buf[i] - 48)
                if mant > 0:
                    ndig += 1
            else:
                exp10 += 1
            digits += 1
            i += 1
        if i < n and buf[i] == 46:  # .
            i += 1
            while i < n and 48 <= buf[i] <= 57:
                if ndig < 18:
                    mant = mant * 10 + (buf[i] - 48)
                    exp10 -= 1
                    if mant > 0:
                        ndig += 1
                digits += 1
                i += 1
        if digits == 0:
            return count, _BAD_NUMBER, _line_end(buf, i, n)
        if i < n and (buf[i] == 101 or buf[i] == 69):  # e E
            i += 1
            eneg = False
            if i < n and (buf[i] == 45 or buf[i] == 43):
                eneg = buf[i] == 45
                i += 1
            e = 0
            ed = 0
            while i < n and 48 <= buf[i] <= 57:
                if e < 100000:
                    e = e * 10 + (buf[i] - 48)
                i += 1
                ed += 1
            if ed == 0:
                return count, _BAD_NUMBER, _line_end(buf, i, n)
            exp10 += -e if eneg else e
        if i < n and not _is_space(buf[i]):
            return count, _BAD_NUMBER, _line_end(buf, i, n)
        v = float(mant)
        if exp10 < 0:
            if exp10 >= -22:
                v = v / pow10[-exp10]
            else:
                v = v * 10.0**exp10
        elif exp10 > 0:
            if exp10 <= 22:
                v = v * pow10[exp10]
            else:
                v = v * 10.0**exp10
        if not np.isfinite(v):
            return count, _BAD_NUMBER, _line_end(buf, i, n)
        out[count] = -v if neg else v
        count += 1


@numba.njit(cache=True, nogil=True, parallel=True)
def parse_all(
    buf: NDArray[np.uint8], n_chunks: int, pow10: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.float32], NDArray[np.int8], NDArray[np.int8]]:
    """Parse every line of ``buf`` in one parallel pass.

    The buffer is cut into ``n_chunks`` byte ranges; a first pass counts the newlines of each,
    so every chunk knows the number of the first line that starts inside it and parses the lines
    starting in its range straight into their rows.

    Returns
    -------
    head : (L, 4) float64
        First four values of each line.
    tail : (L, 3) float32
        Values 5-7 (PTX colour).
    counts : (L,) int8
        Number of values on each line.
    errors : (L,) int8
        0 ok, 1 not a number, 2 more than 7 values.
    """
    n = buf.shape[0]
    size = (n + n_chunks - 1) // n_chunks
    nl = np.zeros(n_chunks + 1, dtype=np.int64)
    for c in prange(n_chunks):
        k = 0
        for i in range(c * size, min(n, (c + 1) * size)):
            k += buf[i] == 10
        nl[c + 1] = k
    for c in range(n_chunks):
        nl[c + 1] += nl[c]
    n_lines = nl[n_chunks] + (1 if n > 0 and buf[n - 1] != 10 else 0)
    head = np.zeros((n_lines, 4), dtype=np.float64)
    tail = np.zeros((n_lines, 3), dtype=np.float32)
    counts = np.zeros(n_lines, dtype=np.int8)
    errors = np.zeros(n_lines, dtype=np.int8)
    for c in prange(n_chunks):
        lo, hi = c * size, min(n, (c + 1) * size)
        s = lo
        li = nl[c]
        if lo > 0 and buf[lo - 1] != 10:  # the line holding `lo` belongs to an earlier chunk
            while s < n and buf[s] != 10:
                s += 1
            s += 1
            li += 1
        vals = np.empty(_MAX_VALUES, dtype=np.float64)
        while s < hi:
            cnt, err, e = _parse_line(buf, s, n, vals, pow10)  # e: the line's end
            for j in range(min(cnt, 4)):
                head[li, j] = vals[j]
            for j in range(4, cnt):
                tail[li, j - 4] = vals[j]
            counts[li] = cnt
            errors[li] = err
            li += 1
            s = e + 1
    return head, tail, counts, errors
