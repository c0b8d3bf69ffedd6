"""Typed, documented configs, and the glue that turns their fields into command-line flags.

A config is a frozen dataclass whose fields each carry a docstring (a string literal right
under the field). ``field_docs`` reads those strings so that ``--help`` shows them.
"""

from __future__ import annotations

import argparse
import ast
import dataclasses
import inspect
import itertools
import numbers
import textwrap
import types
import typing
from collections.abc import Callable, Mapping
from typing import Any, Literal, TypeVar, get_args, get_origin

T = TypeVar("T")


def field_docs(cls: type) -> dict[str, str]:
    """Docstrings of a dataclass's fields: {name: the string literal under the field}."""
    docs: dict[str, str] = {}
    for klass in reversed(cls.__mro__):
        if not dataclasses.is_dataclass(klass):
            continue
        try:
            tree = ast.parse(textwrap.dedent(inspect.getsource(klass)))
        except (OSError, TypeError):
            continue
        body = tree.body[0].body  # type: ignore[attr-defined]
        for node, following in itertools.pairwise(body):
            if (
                isinstance(node, ast.AnnAssign)
                and isinstance(node.target, ast.Name)
                and isinstance(following, ast.Expr)
                and isinstance(following.value, ast.Constant)
                and isinstance(following.value.value, str)
            ):
                docs[node.target.id] = " ".join(following.value.value.split())
    return docs


def dataclass_from_dict(cls: type[T], value: Any, name: str) -> T | None:
    """``value`` as a ``cls``: None and ``cls`` instances pass through; a dict of its fields (as
    JSON gives them back: lists where tuples are meant) is converted. ``name`` labels errors."""
    if value is None or isinstance(value, cls):
        return value
    if not isinstance(value, Mapping):
        raise TypeError(
            f"{name} must be a {cls.__name__}, a dict of its fields or None, "
            f"got {type(value).__name__}"
        )
    known = {f.name for f in dataclasses.fields(cls)}  # type: ignore[arg-type]
    unknown = sorted(set(value) - known)
    if unknown:
        raise ValueError(f"{name}: {cls.__name__} has no field(s) {', '.join(unknown)}")
    hints = typing.get_type_hints(cls)
    for key, item in value.items():
        if not _matches(item, hints[key]):
            raise ValueError(
                f"{name}.{key} must be {_type_text(hints[key])}, got {item!r} "
                f"({type(item).__name__})"
            )
    return cls(**{k: tuple(v) if isinstance(v, list) else v for k, v in value.items()})


def _matches(value: Any, hint: Any) -> bool:
    """Whether ``value`` (as JSON or flags give it: lists for tuples) fits type ``hint``, for
    the types configs use; others (and nested dataclasses, checked on their own) pass."""
    origin, args = get_origin(hint), get_args(hint)
    if hint is Any:
        return True
    if origin in (typing.Union, types.UnionType):
        return any(_matches(value, arg) for arg in args)
    if origin is Literal:
        return value in args
    if hint is type(None):
        return value is None
    if hint is bool:
        return isinstance(value, bool)
    if hint is int:
        return isinstance(value, numbers.Integral) and not isinstance(value, bool)
    if hint is float:
        return isinstance(value, numbers.Real) and not isinstance(value, bool)
    if hint is str:
        return isinstance(value, str)
    if origin is tuple:
        if not isinstance(value, (list, tuple)):
            return False
        if len(args) == 2 and args[1] is Ellipsis:
            return all(_matches(item, args[0]) for item in value)
        return len(value) == len(args) and all(map(_matches, value, args))
    return True


def _type_text(hint: Any) -> str:
    """A type as an error message names it (``float | None``, ``tuple[int, ...]``)."""
    if isinstance(hint, type) and get_origin(hint) is None:
        return hint.__name__
    return str(hint).replace("typing.", "")


def flag_name(field_name: str, prefix: str = "") -> str:
    """The command-line flag of a field: ``batch_size`` with prefix ``td3`` is --td3-batch-size."""
    return "--" + _dest(field_name, prefix).replace("_", "-")


def add_dataclass_arguments(
    parser: argparse._ActionsContainer,
    cls: type,
    skip: tuple[str, ...] = (),
    prefix: str = "",
    defaults: Mapping[str, Any] | None = None,
) -> None:
    """Add one ``--flag`` per field of dataclass ``cls`` to a parser or argument group.

    With ``prefix`` "td3", field ``batch_size`` becomes ``--td3-batch-size`` (dest
    ``td3_batch_size``). A flag that is not given leaves no attribute in the namespace
    (``overrides_from_args`` reads only the given ones), so optional numbers can be set to None
    with the word ``none``. Tuples take their items (``tuple[int, ...]``: one or more ints;
    ``tuple[float, float]``: two floats); booleans get ``--no-`` twins. Fields
    in ``skip``, and fields that are dataclasses themselves (give them their own group), get no
    flag. ``defaults`` overrides the default shown in the help, per field (e.g. a preset's).
    """
    docs = field_docs(cls)
    hints = typing.get_type_hints(cls)
    for field in dataclasses.fields(cls):
        hint = hints[field.name]
        base = _base_type(hint)
        if field.name in skip or dataclasses.is_dataclass(base):
            continue
        kwargs: dict[str, Any] = {
            "default": argparse.SUPPRESS,
            "dest": _dest(field.name, prefix),
        }
        if defaults is not None and field.name in defaults:
            default = defaults[field.name]
        else:
            default = field.default if field.default is not dataclasses.MISSING else None
        help_text = docs.get(field.name, "")
        choices = _literal_choices(hint)
        if base is bool:
            kwargs["action"] = argparse.BooleanOptionalAction
        elif choices:
            kwargs["choices"] = choices
        elif base is tuple:
            item, count = _tuple_items(hint)
            kwargs["type"] = item
            kwargs["nargs"] = count
            kwargs["metavar"] = item.__name__.upper()
        elif base in (int, float) and _optional(hint):
            kwargs["type"] = none_or(base)
            kwargs["metavar"] = f"{base.__name__.upper()}|none"
            help_text += ' ("none" for None)'
        else:
            kwargs["type"] = base
            if prefix:
                kwargs["metavar"] = field.name.upper()
        help_text += f" (default: {_show(default)})"
        parser.add_argument(
            flag_name(field.name, prefix), help=help_text.replace("%", "%%"), **kwargs
        )


def overrides_from_args(args: argparse.Namespace, cls: type, prefix: str = "") -> dict[str, Any]:
    """The fields of ``cls`` that were given on the command line (flags of
    ``add_dataclass_arguments`` with the same ``prefix``), as {field name: value}."""
    out = {}
    for field in dataclasses.fields(cls):
        dest = _dest(field.name, prefix)
        if hasattr(args, dest):
            value = getattr(args, dest)
            out[field.name] = tuple(value) if isinstance(value, list) else value
    return out


def none_or(base: Callable[[str], T]) -> Callable[[str], T | None]:
    """An argparse ``type`` that reads ``none`` (any case) as None, anything else with ``base``."""

    def parse(text: str) -> T | None:
        return None if text.strip().lower() == "none" else base(text)

    parse.__name__ = getattr(base, "__name__", "value")  # argparse's "invalid float value"
    return parse


def _dest(field_name: str, prefix: str) -> str:
    return f"{prefix}_{field_name}" if prefix else field_name


def _show(default: Any) -> str:
    if isinstance(default, tuple):
        return " ".join(str(v) for v in default)
    return str(default)


def _optional(hint: Any) -> bool:
    return get_origin(hint) in (typing.Union, types.UnionType) and type(None) in get_args(hint)


def _literal_choices(hint: Any) -> list[Any] | None:
    if get_origin(hint) is Literal:
        return list(get_args(hint))
    return None


def _tuple_items(hint: Any) -> tuple[type, int | str]:
    """Item type and argparse ``nargs`` of a (possibly optional) tuple hint."""
    if get_origin(hint) in (typing.Union, types.UnionType):
        hint = next(a for a in get_args(hint) if a is not type(None))
    args = get_args(hint)
    if len(args) == 2 and args[1] is Ellipsis:
        return args[0], "+"
    return args[0], len(args)


def _base_type(hint: Any) -> Any:
    origin = get_origin(hint)
    if origin in (typing.Union, types.UnionType):
        args = [a for a in get_args(hint) if a is not type(None)]
        return _base_type(args[0])
    if origin is Literal:
        return type(get_args(hint)[0])
    if origin is tuple:
        return tuple
    return hint
