"""Reading and writing ilfo's files with clear errors: a damaged file is a ValueError naming it.

msgpack (flax serialization) for parameters, ``.npz`` (never unpickled) for arrays, JSON for
settings, each written through a temporary file and a rename where a reader must never see half
of it.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import tomllib
import zipfile
from collections.abc import Iterator
from pathlib import Path
from typing import Any, TypeVar

import flax.serialization
import jax
import numpy as np

from ilfo.npz_check import check_npz

T = TypeVar("T")


@contextlib.contextmanager
def naming(path: str | Path) -> Iterator[None]:
    """Inside it, an OSError that names no file (a write to a full disk, a failed flush) is
    raised again naming ``path``, which the command line prints (``ilfo.cli``)."""
    try:
        yield
    except OSError as err:
        if err.filename is not None:
            raise
        raise OSError(err.errno, err.strerror or str(err), str(path)) from err


def temporary_name(path: str | Path) -> Path:
    """A temporary file beside ``path`` for a write then rename, its own to this process (two
    processes writing ``path`` at once must not share one: the second rename finds none)."""
    path = Path(path)
    return path.with_name(f".{path.name}.{os.getpid()}.tmp")


def write_bytes_atomic(path: str | Path, data: bytes) -> None:
    """Write ``data`` to ``path`` through a temporary file and a rename: a reader (or a kill)
    never sees a half-written file; an OSError (a full disk) names ``path``."""
    path = Path(path)
    tmp = temporary_name(path)
    try:
        with naming(path):
            tmp.write_bytes(data)
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)


def write_json_atomic(path: str | Path, value: Any) -> None:
    """Write ``value`` as JSON to ``path`` through a temporary file and a rename: a reader (or a
    kill) never sees a half-written file; an OSError (a full disk) names ``path``."""
    path = Path(path)
    tmp = temporary_name(path)
    try:
        with naming(path):
            tmp.write_text(json.dumps(value, indent=2) + "\n")
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)


def parse_json(text: str, path: str | Path) -> Any:
    """``text``, the contents of the JSON file ``path``, parsed; a one-line ValueError naming
    the file where it is not JSON or nests too deeply to parse (a RecursionError else)."""
    try:
        return json.loads(text)
    except json.JSONDecodeError as err:
        raise ValueError(f"{path} is not valid JSON ({err})") from None
    except RecursionError:
        raise ValueError(f"{path} is not readable JSON: its values are nested too deeply") from None


def read_json(path: str | Path) -> Any:
    """The JSON file at ``path``, parsed (``parse_json``); a ValueError naming it where it is
    not UTF-8 text."""
    path = Path(path)
    return parse_json(_read_text(path), path)


def _read_text(path: Path) -> str:
    try:
        return path.read_text(encoding="utf-8")
    except UnicodeDecodeError as err:
        raise ValueError(f"{path} is not UTF-8 text ({err.reason} at byte {err.start})") from None


def sync_tree(path: str | Path) -> None:
    """Flush ``path`` to the disk: every file under it, then each directory bottom-up, so that
    a rename of ``path`` made after this survives a power loss with its contents (a rename
    alone can reach the disk before the data it names)."""
    for root, _, files in os.walk(path, topdown=False):
        for name in files:
            sync_dir(os.path.join(root, name))  # a file is flushed the same way
        sync_dir(root)


def sync_dir(path: str | Path) -> None:
    """Flush a directory's entries (the names created, renamed or removed in it), or a file's
    contents, to the disk."""
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def check_new_copy_dir(source: str | Path, out: str | Path) -> None:
    """Refuse ``out`` as the directory for a copy of ``source``: FileExistsError where it
    exists, ValueError where it lies inside ``source`` (the copy would land in what it copies)."""
    source, out = Path(source).resolve(), Path(out).resolve()
    if out.exists():
        raise FileExistsError(f"{out} exists: choose a new directory for the copy")
    if out.is_relative_to(source):
        raise ValueError(f"{out} is inside {source}: choose a directory outside it")


def file_sha256(path: str | Path) -> str:
    """The sha256 of a file's bytes, hex (read in 1 MiB blocks: a demo file can be tens of MB)."""
    digest = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def load_msgpack(template: T, path: str | Path, what: str) -> T:
    """``path``'s flax msgpack restored onto ``template``, checked to have its structure and
    every array's shape; a ValueError names the file otherwise.

    ``what`` says what the file holds ("policy", "agent checkpoint"), for the messages."""
    path = Path(path)
    try:
        data = path.read_bytes()
        restored = flax.serialization.from_bytes(template, data)
    except (ValueError, KeyError, TypeError, IndexError, AttributeError) as err:
        # msgpack's errors (truncated, garbage) are ValueErrors; a foreign tree, Key/TypeError.
        raise ValueError(f"{path} is not a readable {what} file ({err})") from None
    expected = jax.tree_util.tree_leaves_with_path(template)
    got = jax.tree_util.tree_leaves(restored)
    if len(expected) != len(got):
        raise ValueError(f"{path}: the {what} does not have this run's structure")
    for (key, want), have in zip(expected, got, strict=True):
        want_shape, have_shape = np.shape(want), np.shape(have)
        if want_shape != have_shape:
            raise ValueError(
                f"{path}: {what} entry {jax.tree_util.keystr(key)} has shape {have_shape}, this "
                f"run's config makes {want_shape} (were the env or the network sizes changed?)"
            )
    return restored


def load_npz(path: str | os.PathLike[str], what: str) -> dict[str, np.ndarray]:
    """Every array of an ``.npz`` written by ilfo (never unpickled), or a ValueError naming the
    file: not a zip archive, truncated, or holding objects."""
    path = Path(path)
    if not zipfile.is_zipfile(path):
        raise ValueError(f"{path} is not a {what} file (not an .npz archive)")
    check_npz(path, f"{what} file")
    try:
        with np.load(path, allow_pickle=False) as archive:
            return {k: archive[k] for k in archive.files}
    except ValueError as err:
        if "allow_pickle" in str(err):
            raise ValueError(f"{path}: {what} file holds Python objects, not arrays") from None
        raise ValueError(f"{path} is not a readable {what} file ({err})") from None
    except (zipfile.BadZipFile, OSError, EOFError, KeyError) as err:
        raise ValueError(f"{path} is not a readable {what} file ({err}); truncated?") from None


def read_settings_file(path: str | Path) -> dict[str, Any]:
    """A JSON (or TOML, by its suffix) file of settings, as a dict; clear errors for a missing,
    damaged or non-object file."""
    path = Path(path)
    if path.is_dir():
        hint = f": pass {path / 'config.json'}" if (path / "config.json").is_file() else ""
        raise ValueError(f"{path} is a directory, not a settings file{hint}")
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such settings file")
    if path.suffix != ".toml":
        raw = read_json(path)
    else:
        try:
            raw = tomllib.loads(_read_text(path))
        except tomllib.TOMLDecodeError as err:
            raise ValueError(f"{path} is not valid TOML ({err})") from None
        except RecursionError:
            raise ValueError(f"{path} is not readable TOML: nested too deeply") from None
    if not isinstance(raw, dict):
        raise ValueError(f"{path} must hold an object of settings, not {type(raw).__name__}")
    return raw
