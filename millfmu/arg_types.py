"""argparse types shared by the commands: a value that does not parse or lies out of range
is refused by argparse (exit status 2) with what is allowed."""

from __future__ import annotations

import argparse
import math


def whole_number(lo: int, hi: int | None = None, why: str = ""):
    """An argparse type: a whole number >= ``lo`` (and <= ``hi`` where given; ``why`` says
    where that bound comes from)."""
    allowed = f"a whole number >= {lo}" if hi is None else f"a whole number from {lo} to {hi}{why}"

    def parse(text: str) -> int:
        try:
            n = int(text)
        except ValueError:
            n = None
        if n is None or n < lo or (hi is not None and n > hi):
            raise argparse.ArgumentTypeError(f"{text!r}: allowed {allowed}")
        return n

    return parse


def positive_number(text: str) -> float:
    """An argparse type: a finite number > 0."""
    try:
        v = float(text)
    except ValueError:
        v = math.nan
    if not (math.isfinite(v) and v > 0):
        raise argparse.ArgumentTypeError(f"{text!r}: allowed a finite number > 0")
    return v
