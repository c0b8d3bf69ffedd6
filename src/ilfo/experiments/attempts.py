"""A sweep run's attempts file, ``attempts/NAME.jsonl``: one JSON object a line, appended by
the processes that start and end its workers (``sweep.record_attempt``).

Every record has its ``event``, ``time``, ``host`` and ``pid``: ``launch`` (the sweep process
started a worker: the worker's pid, the CPUs chosen for it and the sweep process's own
``sweep_pid``), ``start`` (the worker itself: its pid, CPUs and threads), ``end`` (with a
``status``; the pid of the worker it ends, also where the sweep process records a worker that
died without its own) and ``reset`` (the failures before it no longer count). Records written
before ilfo kept pids have none on their ends, each of which ends the latest start.
"""

from __future__ import annotations

import json
import os
import socket
import time
import warnings
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ilfo.files import naming

if TYPE_CHECKING:
    from ilfo.experiments.sweep import Sweep

WORKER_EVENTS = ("launch", "start")
"""The records that claim CPUs for a worker until its end."""
_RECORD_START = b'{"event": "'
"""How every record's line begins: a line that begins so and does not parse is one that a kill
cut short, not damage."""


def read_records(path: Path) -> list[dict[str, Any]]:
    """The records of the attempts file at ``path``, oldest first; [] without one.

    A line that a kill cut short is skipped; so is any other line that is not a JSON object in
    UTF-8, with a warning naming the file and those lines (a damaged file is no reason to stop
    a sweep: the run's good records are kept)."""
    try:
        raw = path.read_bytes()
    except FileNotFoundError:
        return []
    records, damaged = [], []
    for number, line in enumerate(raw.splitlines(), 1):
        if not line.strip():
            continue
        try:
            record = json.loads(line.decode("utf-8"))
        except UnicodeDecodeError:
            damaged.append(number)
            continue
        except (json.JSONDecodeError, RecursionError):
            if not line.startswith(_RECORD_START):
                damaged.append(number)
            continue
        if isinstance(record, dict):
            records.append(record)
        else:
            damaged.append(number)
    if damaged:
        lines = ", ".join(map(str, damaged[:5])) + (" ..." if len(damaged) > 5 else "")
        warnings.warn(
            f"{path} is damaged: line(s) {lines} are not attempt records (not UTF-8 JSON "
            "objects); skipped",
            stacklevel=3,
        )
    return records


def append_record(path: Path, event: str, **fields: Any) -> None:
    """Append one record: ``event`` with the time, host and this process's pid (``fields``
    may give another pid: the worker's, where the sweep process records for it)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    line = {"event": event, "time": time.time(), "host": socket.gethostname()}
    line |= {"pid": os.getpid(), **fields}
    with naming(path), path.open("ab+") as f:  # appends go to the end whatever was read
        end = f.seek(0, os.SEEK_END)
        if end:
            f.seek(end - 1)
            if f.read(1) != b"\n":  # a line a kill cut short: ended, or this one is glued on
                f.write(b"\n")
        f.write((json.dumps(line) + "\n").encode())


def unended_workers(records: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """The latest launch or start record of each worker that no end record follows, matched
    by pid; an end without a pid (written before ilfo kept them, or for a worker whose pid is
    unknown) ends the latest of them."""
    open_: dict[Any, dict[str, Any]] = {}
    for record in records:
        pid = record.get("pid")
        if record.get("event") in WORKER_EVENTS:
            open_.pop(pid, None)  # re-inserted: the latest record last
            open_[pid] = record
        elif record.get("event") == "end":
            if pid is not None and pid in open_:
                del open_[pid]
            elif pid is None and open_:
                open_.popitem()
    return list(open_.values())


def claimed_cpus(record: dict[str, Any]) -> set[int]:
    """The CPUs a launch or start record names (none where its ``cpus`` are not a list of
    CPU ids: a damaged record claims nothing)."""
    cpus = record.get("cpus")
    if not isinstance(cpus, list):
        return set()
    return {c for c in cpus if isinstance(c, int) and not isinstance(c, bool) and c >= 0}


def read_attempts(sweep: Sweep, name: str) -> list[dict[str, Any]]:
    """The run's attempt records, oldest first (``attempts.read_records``: a torn last line,
    from a kill, is skipped; damaged lines are skipped with a warning naming the file)."""
    return read_records(sweep.attempts_file(name))


def record_attempt(sweep: Sweep, name: str, event: str, **fields: Any) -> None:
    """Append one attempt record with the host, time and pid (``attempts.append_record``):
    ``launch``, ``start``, ``end`` (with a status: done, interrupted, error, killed, busy) or
    ``reset`` (the failures before it no longer count)."""
    append_record(sweep.attempts_file(name), event, **fields)
