"""A run's metrics: one row per episode in ``metrics.csv`` and the same scalars as TensorBoard
events in ``tb/``, which agree on what a resumed run holds (see ``MetricsLog``)."""

from __future__ import annotations

import csv
import os
import time
from pathlib import Path
from typing import Any

METRIC_FIELDS = [
    "step",
    "episode",
    "wall_time",
    "steps_per_s",
    "proxy_return",
    "train_task_return",
    "critic_loss",
    "actor_loss",
    "eval_score",
    "eval_return",
    "eval_score_norm",
    "eval_return_norm",
    "eval_ot_distance",
    "reward_mean",
    "reward_loss",
    "reward_accuracy",
]


class MetricsLog:
    """Appends episode rows to ``RUN/metrics.csv`` and their numbers to TensorBoard events.

    ``resume_step`` (a resumed run: its checkpoint's step, after which ``truncate_metrics``
    dropped the CSV's rows) starts the events with TensorBoard's purge marker at
    ``resume_step + 1``, which hides the events a killed process logged after its checkpoint.
    ``flush`` (at each checkpoint) writes the events to the file, so that a kill after a
    checkpoint loses none logged before it (each CSV row is written when logged)."""

    def __init__(self, run_dir: Path, resume_step: int | None = None) -> None:
        self.path = Path(run_dir) / "metrics.csv"
        self._tb_dir = Path(run_dir) / "tb"
        self._purge_step = None if resume_step is None else resume_step + 1
        self._tb: TensorBoardLog | None = None  # opened with the first row

    def write(self, row: dict[str, Any]) -> None:
        """Append one row (keys of ``METRIC_FIELDS``; others are ignored by the CSV)."""
        from ilfo.files import naming

        with naming(self._tb_dir):  # a full disk: the message names where
            if self._tb is None:
                self._tb = TensorBoardLog(self._tb_dir, purge_step=self._purge_step)
            self._tb.add_scalars(
                {k: v for k, v in row.items() if k not in ("step", "episode")}, row["step"]
            )
        new = not self.path.exists()
        with naming(self.path), self.path.open("a", newline="") as f:
            writer = csv.DictWriter(f, fieldnames=METRIC_FIELDS)
            if new:
                writer.writeheader()
            writer.writerow({k: row.get(k, "") for k in METRIC_FIELDS})

    def flush(self) -> None:
        """Write the TensorBoard events logged so far to disk, and flush metrics.csv (closed per
        row) to the disk, so that a checkpoint saved after this survives a power loss with
        every row up to its step (resume never logs them again)."""
        from ilfo.files import naming, sync_dir

        if self._tb is not None:
            with naming(self._tb_dir):
                self._tb.flush()
        if self.path.exists():
            with naming(self.path):
                sync_dir(self.path)

    def close(self) -> None:
        """Flush and close the events file."""
        if self._tb is not None:
            self._tb.close()
            self._tb = None


class TensorBoardLog:
    """Scalars to a TensorBoard events file in ``logdir``, written synchronously and flushed by
    ``flush``: tensorboardX's SummaryWriter queues events for a thread whose flush does not wait
    for the queue, so a kill could lose events logged before a checkpoint.

    ``purge_step`` S (a resumed run: its checkpoint's step + 1) starts the file with
    TensorBoard's session-start marker at S, which hides the events at S and after that an
    earlier process wrote, as metrics.csv drops those rows."""

    def __init__(self, logdir: Path, purge_step: int | None = None) -> None:
        from tensorboardX.event_file_writer import EventsWriter
        from tensorboardX.proto.event_pb2 import Event, SessionLog
        from tensorboardX.summary import scalar

        self._event, self._scalar = Event, scalar
        logdir.mkdir(parents=True, exist_ok=True)
        # One file per process and start: names hold the time in seconds only.
        suffix = f".{os.getpid()}.{purge_step or 0}"
        self._writer = EventsWriter(str(logdir / "events"), filename_suffix=suffix)
        if purge_step is not None:
            start = SessionLog(status=SessionLog.START)
            event = Event(wall_time=time.time(), step=purge_step, session_log=start)
            self._writer.write_event(event)

    def add_scalars(self, values: dict[str, Any], step: int) -> None:
        """Log every int or float of ``values`` at ``step``."""
        now = time.time()
        for tag, value in values.items():
            if isinstance(value, int | float) and not isinstance(value, bool):
                summary = self._scalar(tag, float(value))
                self._writer.write_event(self._event(wall_time=now, step=step, summary=summary))

    def flush(self) -> None:
        """Write what was logged to the file."""
        self._writer.flush()

    def close(self) -> None:
        """Flush and close the file."""
        self._writer.close()


def truncate_metrics(path: Path, step: int) -> None:
    """Drop rows logged after the checkpoint: the resumed run writes them again. A row cut
    short by a kill (fewer fields than the header) is dropped too. The file is replaced
    through a rename, so that a kill here loses nothing; one that is not UTF-8 CSV is a
    ValueError naming it, and left as it is."""
    from ilfo.files import naming, temporary_name

    if not path.is_file():
        return
    rows = [r for r in _rows(path) if None not in r.values()]
    tmp = temporary_name(path)
    try:
        with naming(path), tmp.open("w", newline="") as f:
            writer = csv.DictWriter(f, fieldnames=METRIC_FIELDS)
            writer.writeheader()
            for row in rows:
                logged = row.get("step") or ""  # a header without one: no row is kept
                if logged.isdigit() and int(logged) <= step:
                    writer.writerow(row)
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)


def read_metrics(run_dir: Path) -> list[dict[str, str]]:
    """The rows of a run's metrics.csv (a ValueError names one that is not UTF-8 CSV)."""
    return _rows(Path(run_dir) / "metrics.csv")


def _rows(path: Path) -> list[dict[str, str]]:
    try:
        with path.open(newline="", encoding="utf-8") as f:
            return list(csv.DictReader(f))
    except UnicodeDecodeError as err:
        raise ValueError(f"{path} is not UTF-8 text ({err.reason}): damaged") from None
    except csv.Error as err:
        raise ValueError(f"{path} is not a readable metrics file ({err})") from None
