"""Writing a command's output file so that a failed run leaves what was there whole, as
`lidar-har dataset` does (temporary names, renamed at the end). Needs no PyTorch."""

from __future__ import annotations

import json
import math
import os
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path


class OutputError(Exception):
    pass


def prepare_output(path: Path) -> None:
    """Makes `path`'s folder and checks that it takes files: before the minutes of work whose
    result goes there, not after them."""
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise OutputError(f"{path}: cannot make its folder {path.parent}: {err.strerror or err}") from err
    if not os.access(path.parent, os.W_OK | os.X_OK):
        raise OutputError(f"{path}: its folder {path.parent} is not writable")


@contextmanager
def replaced_when_done(out: Path) -> Iterator[Path]:
    """Yields a temporary path beside `out` to write to; moves it to `out` when the block ends
    and removes it when the block raises, so a failed or interrupted export never deletes or
    half-writes the model already at `out` (`--init-from M --out M` names one)."""
    prepare_output(out)
    temp = out.with_name(out.name + ".tmp")
    try:
        yield temp
    except BaseException:
        temp.unlink(missing_ok=True)
        raise
    os.replace(temp, out)


def set_aside(temp: Path, out: Path) -> Path:
    """Moves a written but refused `temp` to `<out's stem>.rejected<suffix>` and returns that
    path: it holds the run's weights, to inspect or to start from."""
    rejected = out.with_name(f"{out.stem}.rejected{out.suffix}")
    os.replace(temp, rejected)
    return rejected


def report_json(report) -> str:
    """`report` as JSON text, a non-finite number (a diverged epoch's loss, the accuracy of no
    window) as null: Python's default writes a bare `NaN`, which is no JSON, and a reader
    (`lidar-har evaluate`) then cannot read the report at all."""
    return json.dumps(finite_or_none(report), indent=2, allow_nan=False) + "\n"


def finite_or_none(value):
    """`value` with every non-finite float inside it replaced by None."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {key: finite_or_none(item) for key, item in value.items()}
    if isinstance(value, (list, tuple)):
        return [finite_or_none(item) for item in value]
    return value
