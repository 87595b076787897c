"""Numbers as fixed-point text, fast: the trace writer's formatter.

A module of its own so that numba is imported only when a trace is written
(:func:`contoursim.traces.write_trace` imports it on first use).
"""

import numpy as np

from ._numba import njit

__all__ = ["csv_rows"]

_MAX_CELL = 21  # sign, up to 16 digits below 2**53, point, comma or newline; 2 spare


def csv_rows(columns, decimals):
    """Rows of comma-separated fixed-point numbers, one line each, as ASCII bytes.

    Parameters
    ----------
    columns : sequence of ndarray, shape (n,)
        The columns, all of one length.
    decimals : sequence of int
        Decimal places of each column; ``abs(value) * 10**decimals`` must stay
        below 2**53 (exact integers in a float).

    Returns
    -------
    bytes
        Each number rounded to its decimals, without trailing zeros (the point
        only when a decimal is left) or a sign on zero: ``-1.25``, ``0``, ``3``.

    Examples
    --------
    >>> csv_rows([np.array([0.0002, 1.0]), np.array([-3.55e-12, -2.5])], [9, 6])
    b'0.0002,0\\n1,-2.5\\n'
    """
    scaled = np.column_stack([np.rint(np.asarray(c, float) * 10.0**d) for c, d in zip(columns, decimals)])
    out = np.empty(scaled.size * _MAX_CELL, np.uint8)
    used = _format(scaled.astype(np.int64), np.asarray(decimals, np.int64), out)
    return out[:used].tobytes()


@njit(cache=True)
def _format(scaled, places, out):
    """Write the rows of `scaled` (integers: value·10**places) into `out`; return the bytes used."""
    n, c = scaled.shape
    digits = np.empty(20, np.uint8)
    ten = np.uint64(10)
    at = 0
    for i in range(n):
        for j in range(c):
            v = scaled[i, j]
            if v < 0:
                out[at] = 45  # "-"
                at += 1
                v = -v
            u = np.uint64(v)  # unsigned: division without the sign fix-ups of Python's floor division, 1.7x faster
            p = places[j]
            k = 0  # digits, least significant first, at least p + 1 of them
            while u > 0 or k <= p:
                q = u // ten
                digits[k] = np.uint8(48 + (u - q * ten))
                u = q
                k += 1
            zeros = 0  # trailing zeros of the decimals
            while zeros < p and digits[zeros] == 48:
                zeros += 1
            for m in range(k - 1, p - 1, -1):
                out[at] = digits[m]
                at += 1
            if zeros < p:
                out[at] = 46  # "."
                at += 1
                for m in range(p - 1, zeros - 1, -1):
                    out[at] = digits[m]
                    at += 1
            out[at] = 44 if j < c - 1 else 10  # "," or newline
            at += 1
    return at
