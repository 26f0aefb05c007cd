"""One mapping from option names to the stages that own them.

Each stage's options are a dataclass (``LiftingOptions``, ``InferenceOptions``); a field
meant for users carries its help text (:func:`option`). From those fields alone come the
named command-line options (:func:`wirescene.cli.options.stage_options`), the
``--set STAGE.FIELD=VALUE`` settings of ``eval``, ``predict`` and ``fit`` and the
``settings`` of :func:`wirescene.fit` / :func:`wirescene.evaluate`
(:meth:`wirescene.fitting.options.FitOptions.with_settings`), so that the three cannot
disagree on a name, a type or a default. ``train all --set`` parses its values with the
same :func:`parse_value`.
"""

from __future__ import annotations

import dataclasses
import json
import numbers
from typing import Any, Mapping

import numpy as np

from wirescene.core.validate import finite_real

__all__ = ["option", "bounded", "exposed_fields", "stage_field", "field_default", "parse_value", "parse_assignment",
           "replace_fields", "check_value", "check_fields", "check_combined"]


def option(default=dataclasses.MISSING, *, help: str, cli: str | None = None, minimum: float = 0,
           maximum: float | None = None, zero: str | None = None, default_factory=dataclasses.MISSING):
    """A dataclass field that users may set: ``help`` is its one-line description on the
    command line; ``cli`` the option name there (default: the field name with dashes);
    ``minimum`` and ``maximum`` the least and largest values a number may take
    (:func:`check_value`), and ``zero`` what 0 means where it is allowed below a positive
    ``minimum`` (e.g. "the bank's own").

    Examples
    --------
    >>> from dataclasses import dataclass
    >>> @dataclass
    ... class Stage:
    ...     weight: float = option(1.0, help="Weight of the prior (0: none).")
    >>> [(f.name, cli) for f, cli, _ in exposed_fields(Stage)]
    [('weight', 'weight')]
    """
    metadata = {"help": help, "cli": cli, "minimum": minimum, "maximum": maximum, "zero": zero}
    if default_factory is not dataclasses.MISSING:
        return dataclasses.field(default_factory=default_factory, metadata=metadata)
    return dataclasses.field(default=default, metadata=metadata)


def bounded(default=dataclasses.MISSING, *, minimum: float, maximum: float | None = None,
            default_factory=dataclasses.MISSING):
    """A dataclass field with no named command-line option (set through ``settings`` /
    ``--set`` only) whose numbers must lie in ``[minimum, maximum]`` (:func:`check_value`).

    Examples
    --------
    >>> from dataclasses import dataclass
    >>> @dataclass
    ... class Stage:
    ...     step: float = bounded(0.25, minimum=0.01)
    >>> exposed_fields(Stage)
    []
    >>> check_value(dataclasses.fields(Stage)[0], 0.0)
    Traceback (most recent call last):
    ...
    ValueError: step must be at least 0.01, got 0.0
    """
    metadata = {"minimum": minimum, "maximum": maximum}
    if default_factory is not dataclasses.MISSING:
        return dataclasses.field(default_factory=default_factory, metadata=metadata)
    return dataclasses.field(default=default, metadata=metadata)


def exposed_fields(cls) -> list[tuple[dataclasses.Field, str, str]]:
    """``[(field, cli_name, help)]`` of the fields of dataclass ``cls`` declared with
    :func:`option`, in declaration order.

    Examples
    --------
    >>> from dataclasses import dataclass
    >>> @dataclass
    ... class Stage:
    ...     road_prior: float = option(0.03, help="Weight of the road prior (0: none).")
    ...     step: float = bounded(0.25, minimum=0.01)  # no command-line option
    ...     n_seeds: int = option(4, help="Seeds.", cli="seeds", minimum=1)
    >>> [(f.name, cli, text) for f, cli, text in exposed_fields(Stage)]
    [('road_prior', 'road-prior', 'Weight of the road prior (0: none).'), ('n_seeds', 'seeds', 'Seeds.')]
    """
    return [(f, f.metadata.get("cli") or f.name.replace("_", "-"), f.metadata["help"])
            for f in dataclasses.fields(cls) if "help" in f.metadata]


def stage_field(cls, name: str) -> dataclasses.Field:
    """The field ``name`` of stage options ``cls``, whose kind and bounds (:func:`check_value`)
    an entry point that takes the option under a name of its own checks too.

    Examples
    --------
    >>> from wirescene.lift import LiftingOptions
    >>> stage_field(LiftingOptions, "camera_pitch").metadata["maximum"]
    45.0
    """
    return next(f for f in dataclasses.fields(cls) if f.name == name)


def field_default(f: dataclasses.Field):
    """The default value of dataclass field ``f`` (its ``default_factory`` called where it has one).

    Examples
    --------
    >>> from dataclasses import dataclass, field
    >>> @dataclass
    ... class Stage:
    ...     steps: int = 8
    ...     sizes: list = field(default_factory=lambda: [1, 2])
    >>> [field_default(f) for f in dataclasses.fields(Stage)]
    [8, [1, 2]]
    """
    return f.default_factory() if f.default is dataclasses.MISSING else f.default


def parse_value(text: str, default):
    """``text`` as a value of an option whose default is ``default``: booleans as
    0/1/true/false, numbers as the default's type, anything else as JSON or else text.
    A ``ValueError`` says what was expected.

    Examples
    --------
    >>> parse_value("2", 1.0), parse_value("false", True), parse_value("[1, 2]", None)
    (2.0, False, [1, 2])
    """
    if isinstance(default, bool):
        key = text.strip().lower()
        if key not in ("0", "1", "true", "false"):
            raise ValueError(f"expected 0, 1, true or false, got {text!r}")
        return key in ("1", "true")
    if isinstance(default, (int, float)):
        kind, what = (int, "an integer") if isinstance(default, int) else (float, "a number")
        try:
            return kind(text)
        except ValueError:  # not int()'s "invalid literal for int() with base 10"
            raise ValueError(f"expected {what}, got {text!r}") from None
    try:
        return json.loads(text)
    except ValueError:
        return text


def parse_assignment(item: str) -> tuple[str, str, str]:
    """``(scope, key, text)`` of ``"SCOPE.KEY=VALUE"``; a ``ValueError`` otherwise.

    Examples
    --------
    >>> parse_assignment("lifting.road_prior=0.05")  # the value stays text: see parse_value
    ('lifting', 'road_prior', '0.05')
    >>> parse_assignment("road_prior=0.05")
    Traceback (most recent call last):
    ...
    ValueError: 'road_prior=0.05' is not SCOPE.KEY=VALUE
    """
    name, sep, text = item.partition("=")
    scope, dot, key = name.strip().partition(".")
    if not sep or not dot or not scope or not key:
        raise ValueError(f"{item!r} is not SCOPE.KEY=VALUE")
    return scope, key.strip(), text


def replace_fields(obj, values: Mapping[str, Any], *, scope: str = ""):
    """``dataclasses.replace(obj, **values)`` with every name checked and every string
    value parsed as the field's default type (:func:`parse_value`); an unknown name is a
    ``ValueError`` that lists the known ones.

    Examples
    --------
    >>> from wirescene.infer.inference import InferenceOptions
    >>> replace_fields(InferenceOptions(), {"box_weight": "50"}).box_weight
    50.0
    """
    fields = {f.name: f for f in dataclasses.fields(obj)}
    changes = {}
    for key, value in values.items():
        if key not in fields:
            where = f"{scope} has" if scope else f"{type(obj).__name__} has"
            raise ValueError(f"{where} no option {key!r}; options: {', '.join(sorted(fields))}")
        default = field_default(fields[key])
        if isinstance(value, str):
            try:
                value = parse_value(value, default)
            except ValueError as exc:
                raise ValueError(f"{scope + '.' if scope else ''}{key}: {exc}") from None
        changes[key] = check_value(fields[key], value, scope=scope)
    out = dataclasses.replace(obj, **changes)
    check_combined(out, scope=scope)
    return out


def check_value(f: dataclasses.Field, value, *, scope: str = ""):
    """``value`` for dataclass field ``f`` if it is of the default's kind (a bool, an
    integer, a finite real number) and within the field's ``minimum`` / ``maximum``
    (:func:`option`, :func:`bounded`); a ``ValueError`` naming the field otherwise. Fields
    whose default is not a number or a bool (None, text, a list) take any value.

    Examples
    --------
    >>> from dataclasses import dataclass
    >>> @dataclass
    ... class Stage:
    ...     n_particles: int = bounded(250, minimum=1)
    ...     weight: float = bounded(1.0, minimum=0)
    >>> n_particles, weight = dataclasses.fields(Stage)
    >>> check_value(n_particles, 100), check_value(weight, 2)  # an int given for a float: the float
    (100, 2.0)
    >>> check_value(n_particles, 2.5, scope="lifting")
    Traceback (most recent call last):
    ...
    ValueError: lifting.n_particles must be an integer, got 2.5
    """
    default = field_default(f)
    name = f"{scope}.{f.name}" if scope else f.name

    def fail(problem: str):
        raise ValueError(f"{name} must be {problem}, got {value!r}")

    if isinstance(default, bool):
        if not isinstance(value, (bool, np.bool_)):
            fail("true or false")
        return bool(value)  # numpy's as Python's: the run records are JSON
    if isinstance(default, numbers.Integral):
        if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Integral):
            fail("an integer")
        value = int(value)
    elif isinstance(default, numbers.Real):
        if isinstance(value, np.bool_) or not finite_real(value):  # an int too large for a float too
            fail("a finite number")
        value = float(value) if isinstance(default, float) else value  # an int given: the same record as the float
    else:
        return value
    low, high, zero = f.metadata.get("minimum"), f.metadata.get("maximum"), f.metadata.get("zero")
    if low is not None and value < low and not (zero and value == 0):
        fail(f"0 ({zero}) or at least {low:g}" if zero else f"at least {low:g}")
    if high is not None and value > high:
        fail(f"at most {high:g}")
    return value


def check_fields(obj, *, scope: str = "") -> None:
    """:func:`check_value` of every field of dataclass ``obj`` (options built directly,
    not through :func:`replace_fields`), then :func:`check_combined`.

    Examples
    --------
    >>> from dataclasses import dataclass
    >>> @dataclass
    ... class Stage:
    ...     step: float = bounded(0.25, minimum=0.01)
    >>> check_fields(Stage())  # passes: returns None
    >>> check_fields(Stage(step=0.0), scope="lifting")
    Traceback (most recent call last):
    ...
    ValueError: lifting.step must be at least 0.01, got 0.0
    """
    for f in dataclasses.fields(obj):
        check_value(f, getattr(obj, f.name), scope=scope)
    check_combined(obj, scope=scope)


def check_combined(obj, *, scope: str = "") -> None:
    """A ``ValueError`` naming the fields of dataclass ``obj`` whose values together break a
    limit (e.g. a grid whose steps and ranges, each within its bounds, would make too many
    cells), as ``obj.combined_problem()`` says where the class defines it; nothing otherwise.

    Examples
    --------
    >>> from dataclasses import dataclass
    >>> @dataclass
    ... class Grid:
    ...     rows: int = bounded(3, minimum=1)
    ...     columns: int = bounded(4, minimum=1)
    ...     def combined_problem(self):
    ...         return (("rows", "columns"), "give too many cells") if self.rows * self.columns > 100 else None
    >>> check_combined(Grid(20, 20), scope="grid")
    Traceback (most recent call last):
    ...
    ValueError: grid.rows, grid.columns give too many cells
    """
    combined = getattr(obj, "combined_problem", None)
    found = combined() if callable(combined) else None
    if found is not None:
        names, problem = found
        raise ValueError(f"{', '.join(f'{scope}.{n}' if scope else n for n in names)} {problem}")
