"""Option types and output checks shared by every command: numbers are checked for
range and finiteness as they are parsed, and outputs for writability before any work
starts, so that a long run never fails at its end on a bad path."""

from __future__ import annotations

import math
import os
from pathlib import Path

import click

#: Counts that must be at least 1 (particles, samples, workers, scenes).
POSITIVE = click.IntRange(min=1)
#: Counts and seeds that may be 0 (iterations, prune-after, seeds).
NON_NEGATIVE = click.IntRange(min=0)


class FiniteFloat(click.ParamType):
    """A finite float, at least ``min`` (NaN and infinities refused)."""

    name = "float"

    def __init__(self, min: float | None = None):
        self.min = min

    def convert(self, value, param, ctx):
        try:
            number = float(value)
        except (TypeError, ValueError):
            self.fail(f"{value!r} is not a number", param, ctx)
        if not math.isfinite(number):
            self.fail(f"{value!r} is not finite", param, ctx)
        if self.min is not None and number < self.min:
            self.fail(f"{number:g} is below the minimum {self.min:g}", param, ctx)
        return number


NON_NEGATIVE_FLOAT = FiniteFloat(min=0.0)


def _first_existing(path: Path) -> Path:
    for candidate in (path, *path.parents):
        if candidate.exists():
            return candidate
    return Path(".")


def _check_creatable(path: Path, option: str) -> None:
    """The directories above ``path`` exist or can be created and written."""
    base = _first_existing(path.parent)
    if not base.is_dir():
        raise click.BadParameter(f"{path}: {base} is a file, not a directory", param_hint=option)
    if not os.access(base, os.W_OK | os.X_OK):
        raise click.BadParameter(f"{path}: {base} is not writable", param_hint=option)


def check_output_file(path: Path | None, option: str) -> None:
    """``path`` can be written as a file (checked before any work starts)."""
    if path is None:
        return
    path = Path(path)
    if path.is_dir():
        raise click.BadParameter(f"{path} is a directory, expected a file path", param_hint=option)
    if path.exists() and not os.access(path, os.W_OK):
        raise click.BadParameter(f"{path} is not writable", param_hint=option)
    _check_creatable(path, option)


def check_output_dir(path: Path | None, option: str) -> None:
    """``path`` is (or can be created as) a writable directory."""
    if path is None:
        return
    path = Path(path)
    if path.exists():
        if not path.is_dir():
            raise click.BadParameter(f"{path} is a file, expected a directory", param_hint=option)
        if not os.access(path, os.W_OK | os.X_OK):
            raise click.BadParameter(f"{path} is not writable", param_hint=option)
        return
    _check_creatable(path, option)


def parse_frames(value: str | None, known: list[str], option: str = "--frames") -> list[str] | None:
    """Comma-separated frame ids, each known and listed once; None keeps all frames."""
    if value is None:
        return None
    frames = [f.strip() for f in value.split(",") if f.strip()]
    if not frames:
        raise click.BadParameter("no frame id given", param_hint=option)
    seen = set()
    for f in frames:
        if f in seen:
            raise click.BadParameter(f"frame {f} is listed twice", param_hint=option)
        seen.add(f)
    unknown = [f for f in frames if f not in set(known)]
    if unknown:
        more = f" (and {len(unknown) - 1} more)" if len(unknown) > 1 else ""
        raise click.BadParameter(f"no frame {unknown[0]} in the dataset{more}", param_hint=option)
    return frames
