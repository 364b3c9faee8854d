"""Option types for the training commands' `argparse` parsers: a value that makes no sense is
refused as the command line is read (`train: error: argument --batch: must be at least 1, got
0`, exit status 2), not after minutes of loading data or fitting, nor silently trained on."""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable


def at_least(minimum: int) -> Callable[[str], int]:
    """An integer of at least `minimum`."""

    def parse(text: str) -> int:
        value = int(text)
        if value < minimum:
            raise argparse.ArgumentTypeError(f"must be at least {minimum}, got {text}")
        return value

    # argparse names the type in its own message for text that is no integer at all.
    parse.__name__ = "int"
    return parse


def number(*, above: float | None = None, minimum: float | None = None,
           below: float | None = None) -> Callable[[str], float]:
    """A finite number greater than `above`, at least `minimum` and below `below` (those
    given): NaN and the infinities make no sense as a rate, a share or a duration."""
    bounds = [f"greater than {above:g}" if above is not None else "",
              f"at least {minimum:g}" if minimum is not None else "",
              f"below {below:g}" if below is not None else ""]
    wanted = " and ".join(b for b in bounds if b)

    def parse(text: str) -> float:
        value = float(text)
        if not (math.isfinite(value) and (above is None or value > above)
                and (minimum is None or value >= minimum) and (below is None or value < below)):
            raise argparse.ArgumentTypeError(f"must be a finite number {wanted}, got {text}")
        return value

    parse.__name__ = "float"
    return parse
