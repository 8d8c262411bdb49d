"""The one number grammar of every text reader in this project (box files, CSV tables, image numbers).

A number is ASCII text of at most :data:`MAX_NUMBER_CHARS` characters:

    number  = [sign] (digits ["." [digits]] | "." digits) [("e" | "E") [sign] digits]
    integer = [sign] digits          (at most :data:`MAX_INT_DIGITS` digits)
    sign    = "+" | "-";  digits = one or more of 0-9

Nothing else is a number: no surrounding whitespace, no ``_`` digit separators, no non-ASCII digits
(``"٣"``), no ``nan`` / ``inf``, no hexadecimal, and no value that overflows a float (``1e999``). Checking
is regex-free and linear in the token: the characters are checked against the grammar's alphabet, and
Python's ``float`` / ``int`` parse exactly this grammar on that alphabet (their extra forms need ``_``,
whitespace or letters other than e/E).

>>> parse_float("-3.5e2"), parse_int("+007")
(-350.0, 7)
>>> parse_float("1_0")
Traceback (most recent call last):
ValueError: '1_0' is not a number: allowed ASCII decimals such as 12, -3.5, .5, 1e-3 (no '_', nan/inf, hex or non-ASCII digits)
"""

from __future__ import annotations

import math

import numpy as np

MAX_NUMBER_CHARS = 64  # a double's shortest repr needs at most 24
MAX_INT_DIGITS = 18  # every such integer fits an int64
_FLOAT_CHARS = frozenset("0123456789+-.eE")
_INT_CHARS = frozenset("0123456789+-")
_NON_FINITE = ("nan", "inf", "infinity")
_ALLOWED = "allowed ASCII decimals such as 12, -3.5, .5, 1e-3 (no '_', nan/inf, hex or non-ASCII digits)"


def shorten(text: str, limit: int = 40) -> str:
    """``repr(text)``, cut to about ``limit`` characters (for error messages about long input)."""
    return repr(text) if len(text) <= limit else f"{text[:limit]!r}… ({len(text)} characters)"


def parse_float(token: str) -> float:
    """The finite float written by ``token`` in the module's grammar, else ValueError saying why."""
    if len(token) > MAX_NUMBER_CHARS:
        raise ValueError(f"{shorten(token)} is too long for a number: allowed at most {MAX_NUMBER_CHARS} characters")
    if not _FLOAT_CHARS.issuperset(token):
        if token.lower().lstrip("+-") in _NON_FINITE:
            raise ValueError(f"non-finite value {token!r}: allowed finite numbers only")
        raise ValueError(f"{token!r} is not a number: {_ALLOWED}")
    try:
        value = float(token)
    except ValueError:
        raise ValueError(f"{token!r} is not a number: {_ALLOWED}") from None
    if not math.isfinite(value):
        raise ValueError(f"{token!r} overflows a 64-bit float (non-finite): allowed magnitudes below 1.8e308")
    return value


def parse_int(token: str) -> int:
    """The integer written by ``token`` (``[sign] digits``, at most 18 digits), else ValueError saying why."""
    if len(token) > MAX_INT_DIGITS + 1 or len(token.lstrip("+-")) > MAX_INT_DIGITS:
        raise ValueError(f"{shorten(token)} is too long for an integer: allowed at most {MAX_INT_DIGITS} digits")
    if not _INT_CHARS.issuperset(token):
        raise ValueError(f"{token!r} is not an integer: allowed ASCII digits with an optional sign")
    try:
        return int(token)
    except ValueError:
        raise ValueError(f"{token!r} is not an integer: allowed ASCII digits with an optional sign") from None


def comma_values(body: str, n_columns: int) -> np.ndarray | None:
    """The (N, ``n_columns``) values of ``body``, lines of comma-separated tokens that the caller has checked to
    hold only number characters in the right layout, in vectorised linear time; None where a token is not a number
    of this grammar (too long, empty, a misplaced sign, point or exponent, not finite): then the caller's
    line-by-line checker decides and names the line."""
    tokens = body.replace("\n", ",").split(",")
    if max(map(len, tokens)) > MAX_NUMBER_CHARS:
        return None
    try:
        values = np.array(list(map(float, tokens)), dtype=float)
    except ValueError:  # an empty token or a misplaced sign, point or exponent
        return None
    return values.reshape(-1, n_columns) if np.isfinite(values).all() else None
