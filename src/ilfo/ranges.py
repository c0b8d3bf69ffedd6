"""Declared ranges and types of config fields, and the one check every config makes of them.

A config dataclass declares what a field accepts in the field's metadata, with the helpers
below, and calls ``check_fields(self)`` first thing in its ``__post_init__``::

    batch_size: int = batch(256)  # an int from 1 to MAX_BATCH
    tau: float = between(0.005, 0.0, 1.0, low_open=True)  # a float in (0, 1]
    reg: float = positive(0.05)  # a finite float > 0

``check_fields`` refuses a value of the wrong type for the field's annotation (a string for a
number, 2.5 or True for an int, None where None is not allowed) and a number outside the
declared range, with a one-line ``SettingError`` (a ValueError) that names the field; it also
converts what it accepts to the annotated type (numpy numbers to int and float, lists to
tuples), so that a config holds what JSON can write. What no declaration says still holds for
every number: a float must be finite, an int at most ``INT32_MAX`` (JAX computes in 32-bit
integers here: a larger count wraps around or overflows far from the setting).
"""

from __future__ import annotations

import dataclasses
import functools
import math
import types
import typing
from collections.abc import Callable
from typing import Any, Literal, get_args, get_origin

from ilfo.config import _matches, flag_name

INT32_MAX = 2**31 - 1
"""The largest int JAX holds without 64-bit mode: the implicit upper bound of an int field."""
SEED_MAX = 2**32 - 1
"""The largest seed: ``jax.random.PRNGKey`` keeps a seed's low 32 bits (2**32 is seed 0's key)
and overflows from 2**63."""
MAX_WIDTH = 2**16
"""The widest hidden layer a config accepts (65,536: one such layer squared is 16 GiB)."""
MAX_BATCH = 2**20
"""The largest batch a config accepts (1,048,576 transitions per gradient step)."""

KEY = "ilfo.range"
"""The field-metadata key of a field's ``Declared``."""


@dataclasses.dataclass(frozen=True)
class Declared:
    """What a numeric field (or each item of a tuple field) accepts, beyond its type."""

    low: float | None = None
    high: float | None = None
    low_open: bool = False
    """Whether ``low`` itself is refused (> low rather than >= low)."""
    high_open: bool = False
    inf: bool = False
    """Whether +inf is a value (``reward_clip``: no clipping)."""
    note: str = ""
    """What the range means, shown after it ("0: off")."""
    kind: str = ""
    """What the value sizes, for ``ilfo.training.resources``: ``widths`` (a tuple of hidden
    layer widths), ``width`` (one width), ``batch`` (samples per gradient step)."""
    check: Callable[[Any, str], Any] | None = None
    """A check of its own, made first, given the value and the field's label (a range that
    another layer checks: the evaluation's episodes, the OT solvers' ``max_iter``)."""
    min_items: int = 0
    """For a tuple field: the fewest items."""

    def contains(self, value: float, integer: bool) -> bool:
        """Whether number ``value`` is in the range (finite unless ``inf``; an int at most
        ``INT32_MAX`` unless ``high`` says otherwise)."""
        if not integer and (math.isnan(value) or (math.isinf(value) and not self.inf)):
            return False  # (an int may be too large for a float: not converted)
        high = INT32_MAX if integer and self.high is None else self.high
        if self.low is not None and (value <= self.low if self.low_open else value < self.low):
            return False
        return high is None or (value < high if self.high_open else value <= high)

    def requirement(self, value: float, integer: bool) -> str:
        """The range as an error message states it, for the refused ``value``: ``>= 1``,
        ``>= 0 and at most 4,294,967,295`` (ints), ``positive and finite``, ``in (0, 1]``."""
        note = f" ({self.note})" if self.note else ""
        if integer and self.high is None and value > INT32_MAX:
            return f"at most {INT32_MAX:,} (the largest 32-bit integer)"
        low, high = _number(self.low), _number(self.high)
        if integer:
            bounds = [f"{'>' if self.low_open else '>='} {low}"] if self.low is not None else []
            bounds += [f"at most {high}"] if self.high is not None else []
            return " and ".join(bounds) + note
        if self.low is not None and self.high is not None:
            brackets = "(" if self.low_open else "[", ")" if self.high_open else "]"
            return f"in {brackets[0]}{low}, {high}{brackets[1]}{note}"
        finite = "" if self.inf else " and finite"
        if self.low is not None:
            if self.low == 0 and self.low_open:
                return f"positive{finite}{note}"
            return f"{'>' if self.low_open else '>='} {low}{finite}{note}"
        if self.high is not None:
            return f"{'<' if self.high_open else '<='} {high}{finite}{note}"
        return f"finite{note}"


class SettingError(ValueError):
    """A field's value refused by its declaration: ``setting`` names the field (``td3.tau``
    once ``within`` a part), the message starts with it."""

    def __init__(self, setting: str, message: str) -> None:
        super().__init__(message)
        self.setting = setting

    def __reduce__(self) -> tuple[Any, ...]:  # sweeps send errors between processes
        return (type(self), (self.setting, str(self)))

    def within(self, part: str, flag: str | None) -> SettingError:
        """This error of a part's config as its ``TrainConfig`` field ``part`` has it: the
        setting named ``part.setting``, and its command-line ``flag`` (None: none)."""
        return SettingError(f"{part}.{self.setting}", f"{part}.{self}{_flagged(flag)}")


def declared(default: Any, **declaration: Any) -> Any:
    """A field with ``default`` whose values ``Declared(**declaration)`` bounds."""
    return dataclasses.field(default=default, metadata={KEY: Declared(**declaration)})


def positive(default: Any, *, inf: bool = False, note: str = "") -> Any:
    """A number > 0 (finite unless ``inf``)."""
    return declared(default, low=0, low_open=True, inf=inf, note=note)


def non_negative(default: Any, *, note: str = "") -> Any:
    """A finite number >= 0."""
    return declared(default, low=0, note=note)


def between(
    default: Any,
    low: float,
    high: float,
    *,
    low_open: bool = False,
    high_open: bool = False,
    note: str = "",
) -> Any:
    """A number from ``low`` to ``high`` (``low_open``, ``high_open``: without that end)."""
    return declared(default, low=low, high=high, low_open=low_open, high_open=high_open, note=note)


def fraction(default: Any) -> Any:
    """A number in (0, 1] (a discount, a Polyak rate)."""
    return between(default, 0.0, 1.0, low_open=True)


def learning_rate(default: Any, *, zero: bool = False) -> Any:
    """An optimiser's learning rate: positive and finite; ``zero``: 0 too (a network frozen)."""
    if zero:
        return non_negative(default, note="0: frozen")
    return positive(default)


def count(default: Any, low: int = 1, high: int | None = None, **more: Any) -> Any:
    """An int >= ``low`` (1), at most ``high`` (``INT32_MAX``)."""
    return declared(default, low=low, high=high, **more)


def width(default: Any) -> Any:
    """One hidden layer's width, from 1 to ``MAX_WIDTH``."""
    return declared(default, low=1, high=MAX_WIDTH, kind="width")


def widths(default: Any, *, min_items: int = 0) -> Any:
    """Hidden layer widths, each from 1 to ``MAX_WIDTH``; at least ``min_items`` of them."""
    return declared(default, low=1, high=MAX_WIDTH, kind="widths", min_items=min_items)


def batch(default: Any) -> Any:
    """Samples per gradient step, from 1 to ``MAX_BATCH``."""
    return declared(default, low=1, high=MAX_BATCH, kind="batch")


def rng_seed(default: Any = 0, **more: Any) -> Any:
    """A seed, from 0 to ``SEED_MAX`` (or a tuple of seeds: ``min_items``)."""
    note = "jax.random.PRNGKey keeps 32 bits"
    return declared(default, low=0, high=SEED_MAX, note=note, **more)


def declaration(cls: type, name: str) -> Declared | None:
    """The ``Declared`` of field ``name`` of dataclass ``cls``; None where it declares none
    (or the field is a dataclass, or not a field)."""
    return next((d for n, _, d in _fields(cls) if n == name), None)


def check_fields(config: Any, flags: str | None = None) -> None:
    """Check every field of dataclass instance ``config`` against its annotation and its
    declaration, converting accepted values to the annotated type (in place, frozen or not).
    A refused value is a ``SettingError`` naming the field; ``flags``: the prefix of the
    fields' command-line flags ("" for unprefixed ones, ``ilfo.config.flag_name``), to name
    the flag too; None names none. Fields that are dataclasses themselves are skipped."""
    # Typed as plain ``type``: mypy takes ``type[Any]`` for unhashable (functools.cache's key).
    cls: type = type(config)
    for name, hint, declared_range in _fields(cls):
        value = getattr(config, name)
        flag = None if flags is None else flag_name(name, flags)
        checked = _checked(value, hint, declared_range, name, flag)
        if checked is not value:
            object.__setattr__(config, name, checked)


@functools.cache
def _fields(cls: type) -> tuple[tuple[str, Any, Declared | None], ...]:
    hints = typing.get_type_hints(cls)
    return tuple(
        (f.name, hints[f.name], f.metadata.get(KEY))
        for f in dataclasses.fields(cls)
        if not dataclasses.is_dataclass(_bare(hints[f.name]))
    )


def _checked(value: Any, hint: Any, ranges: Declared | None, name: str, flag: str | None) -> Any:
    """``value`` of field ``name`` converted to ``hint``, or a ``SettingError``."""
    if ranges is not None and ranges.check is not None:
        try:
            ranges.check(value, name if flag is None else f"{name} ({flag})")
        except ValueError as err:
            raise SettingError(name, str(err)) from None
    if not _matches(value, hint):
        got = f"{value!r} ({type(value).__name__})"
        raise SettingError(name, f"{name} must be {_kind(hint)}, got {got}{_flagged(flag)}")
    value = _converted(value, _bare(hint))
    base = get_origin(_bare(hint)) or _bare(hint)
    if value is None or base not in (int, float, tuple):
        return value
    ranges = ranges or Declared()
    if base is tuple and len(value) < ranges.min_items:
        noun = "width" if ranges.kind == "widths" else "value"
        least = f"at least {ranges.min_items} {noun}{'s' * (ranges.min_items > 1)}"
        raise SettingError(name, f"{name} must hold {least}, got {value}{_flagged(flag)}")
    for item in value if base is tuple else (value,):
        integer = isinstance(item, int)
        if isinstance(item, float | int) and not ranges.contains(item, integer):
            required = ranges.requirement(item, integer)
            if base is tuple:
                items = "widths" if ranges.kind == "widths" else "numbers that are"
                required, shown = f"hold {items} {required}", str(value)
            else:
                required, shown = f"be {required}", f"{value:,}" if integer else repr(value)
            raise SettingError(name, f"{name} must {required}, got {shown}{_flagged(flag)}")
    return value


def _converted(value: Any, hint: Any) -> Any:
    """A value that matches ``hint`` as the type itself (int, float, bool; tuples of them)."""
    if value is None:
        return None
    if hint is bool:
        return value if type(value) is bool else bool(value)
    if hint is int:
        return value if type(value) is int else int(value)
    if hint is float:
        return value if type(value) is float else float(value)
    if get_origin(hint) is tuple:
        args = get_args(hint)
        items = [args[0]] * len(value) if args[-1] is Ellipsis else list(args)
        converted = tuple(_converted(v, h) for v, h in zip(value, items, strict=True))
        same = type(value) is tuple and all(map(_same, converted, value))
        return value if same else converted
    return value


def _same(a: Any, b: Any) -> bool:
    return a is b or (type(a) is type(b) and a == b)


def _bare(hint: Any) -> Any:
    """``X`` of ``X | None`` (an optional field's type), else ``hint``."""
    if get_origin(hint) in (typing.Union, types.UnionType):
        args = [a for a in get_args(hint) if a is not type(None)]
        return args[0] if len(args) == 1 else hint
    return hint


def _kind(hint: Any) -> str:
    """What a type hint accepts, in words (``an integer or none``)."""
    origin, args = get_origin(hint), get_args(hint)
    if origin in (typing.Union, types.UnionType):
        alternatives = [_kind(a) for a in args if a is not type(None)]
        return " or ".join(alternatives) + (" or none" if type(None) in args else "")
    if origin is Literal:
        return "one of " + ", ".join(map(repr, args))
    if origin is tuple:
        if len(args) == 2 and args[1] is Ellipsis:
            return f"a list of {_kind(args[0]).split(' ', 1)[1]}s"
        return f"a list of {len(args)} {_kind(args[0]).split(' ', 1)[1]}s"
    words = {int: "an integer", float: "a number", bool: "true or false", str: "a string"}
    return words.get(hint, getattr(hint, "__name__", str(hint)))


def _number(value: float | None) -> str:
    if isinstance(value, int) and not isinstance(value, bool):
        return f"{value:,}"
    if isinstance(value, float) and value.is_integer() and abs(value) < 1e15:
        return f"{int(value):,}"
    return repr(value)


def _flagged(flag: str | None) -> str:
    return f" ({flag})" if flag else ""


__all__ = [
    "INT32_MAX",
    "MAX_BATCH",
    "MAX_WIDTH",
    "SEED_MAX",
    "Declared",
    "SettingError",
    "batch",
    "between",
    "check_fields",
    "count",
    "declaration",
    "declared",
    "fraction",
    "learning_rate",
    "non_negative",
    "positive",
    "rng_seed",
    "width",
    "widths",
]
