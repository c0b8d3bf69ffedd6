"""A look at an ``.npz`` archive before any of it is read: every member stored or deflated,
none encrypted, and every ``.npy`` header's shape and dtype within what the member holds.

``np.load`` would otherwise fail on such a file with a RuntimeError (encrypted), a
NotImplementedError (another compression method) or a MemoryError (a header declaring terabytes);
here each is a one-line ValueError naming the file and the member. Only numpy is imported, so
that ``ilfo.demos`` stays light.
"""

from __future__ import annotations

import ast
import math
import zipfile
import zlib
from pathlib import Path
from typing import IO

import numpy as np

READ_METHODS = {zipfile.ZIP_STORED: "stored", zipfile.ZIP_DEFLATED: "deflated"}
"""The compression methods numpy writes, and the only ones read."""
DEFLATE_MAX_RATIO = 1032
"""The most that deflate expands its input (a run of one byte); a member that claims more
uncompressed bytes than this times its compressed ones is damaged."""
MAX_HEADER_BYTES = 10_000
"""numpy's own bound on an .npy header (``np.load``'s ``max_header_size``)."""
_OPEN_ERRORS = (zipfile.BadZipFile, zlib.error, OSError, EOFError, KeyError, ValueError)


def check_npz(path: str | Path, what: str = ".npz archive") -> list[str]:
    """The member names of the archive at ``path``, once each member is checked to be readable
    without surprises (see the module); a ValueError naming the file (as ``what``: "replay
    buffer file") and the member otherwise."""
    path = Path(path)
    try:
        archive = zipfile.ZipFile(path)
    except _OPEN_ERRORS as err:
        raise ValueError(f"{path} is not a readable {what} ({err})") from None
    with archive:
        infos = archive.infolist()
        size = path.stat().st_size
        for info in infos:
            _check_member(archive, info, path, size)
    return [info.filename for info in infos]


def _check_member(z: zipfile.ZipFile, info: zipfile.ZipInfo, path: Path, archive_size: int) -> None:
    where = f"{path}: member {info.filename!r}"
    if info.flag_bits & 0x1:
        raise ValueError(f"{where} is encrypted; ilfo reads only unencrypted archives")
    if info.compress_type not in READ_METHODS:
        raise ValueError(
            f"{where} uses compression method {info.compress_type}; only stored and deflated "
            "members (what numpy writes) are read"
        )
    if info.compress_size > archive_size:
        raise ValueError(
            f"{where} claims {info.compress_size:,} compressed bytes, more than the whole file's "
            f"{archive_size:,}: truncated or damaged"
        )
    ratio = 1 if info.compress_type == zipfile.ZIP_STORED else DEFLATE_MAX_RATIO
    if info.file_size > ratio * info.compress_size + 1024:
        raise ValueError(
            f"{where} claims {info.file_size:,} bytes from {info.compress_size:,} "
            f"{READ_METHODS[info.compress_type]}: damaged"
        )
    try:
        with z.open(info) as f:
            header = _npy_header(f, where)
    except (zipfile.BadZipFile, zlib.error, OSError, EOFError) as err:
        raise ValueError(f"{where} is not readable ({err})") from None
    if header is None:
        return  # not an .npy array: numpy returns its bytes as they are
    shape, dtype, offset = header
    if dtype.hasobject:
        return  # pickled objects: refused when read (allow_pickle=False)
    declared = math.prod(shape) * dtype.itemsize
    held = info.file_size - offset
    if declared > held:
        raise ValueError(
            f"{where} declares an array of shape {shape} and dtype {dtype} "
            f"({_bytes(declared)}), but holds only {_bytes(max(held, 0))}: damaged"
        )


def _npy_header(f: IO[bytes], where: str) -> tuple[tuple[int, ...], np.dtype, int] | None:
    """(shape, dtype, bytes before the data) from an .npy member's header; None where the
    member does not start as an .npy file does."""
    magic = f.read(np.lib.format.MAGIC_LEN)
    if not magic.startswith(np.lib.format.MAGIC_PREFIX):
        return None
    version = (magic[-2], magic[-1])
    if len(magic) < np.lib.format.MAGIC_LEN or version not in ((1, 0), (2, 0), (3, 0)):
        raise ValueError(f"{where} is an .npy array of unknown format version {version}")
    length_bytes = 2 if version == (1, 0) else 4
    length = int.from_bytes(f.read(length_bytes), "little")
    if length > MAX_HEADER_BYTES:
        raise ValueError(f"{where} has an .npy header of {length:,} bytes: damaged")
    raw = f.read(length)
    try:
        header = ast.literal_eval(raw.decode("utf-8" if version == (3, 0) else "latin1"))
        shape = tuple(header["shape"])
        dtype = np.lib.format.descr_to_dtype(header["descr"])
        if not all(isinstance(n, int) and not isinstance(n, bool) and n >= 0 for n in shape):
            raise ValueError(f"shape {shape!r}")
    except (ValueError, SyntaxError, TypeError, KeyError, RecursionError, MemoryError) as err:
        raise ValueError(f"{where} has an unreadable .npy header ({err})") from None
    if len(raw) < length:
        raise ValueError(f"{where} has a truncated .npy header")
    return shape, dtype, np.lib.format.MAGIC_LEN + length_bytes + length


def _bytes(n: int) -> str:
    """``n`` bytes in the largest binary unit that keeps it >= 1 (``80.0 TiB``)."""
    for unit in ("B", "KiB", "MiB", "GiB", "TiB"):
        if n < 1024 or unit == "TiB":
            return f"{n:,} {unit}" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1024  # type: ignore[assignment]
    raise AssertionError  # pragma: no cover
