"""What a run shows and hears while it trains in a terminal: its progress bar, and the Ctrl-C
(or SIGTERM) that asks it to stop at the next episode boundary."""

from __future__ import annotations

import contextlib
import signal
from collections.abc import Iterator
from typing import Any


class StopRequest:
    """Set by the first Ctrl-C or SIGTERM; the loop stops at the next episode boundary."""

    requested = False


@contextlib.contextmanager
def stop_requests() -> Iterator[StopRequest]:
    """The first SIGINT/SIGTERM asks the loop to checkpoint and stop after the current episode
    (a run is consistent only between episodes); the second raises KeyboardInterrupt at once."""
    stop = StopRequest()

    def handler(signum: int, frame: Any) -> None:
        if stop.requested:
            raise KeyboardInterrupt
        stop.requested = True
        print("\nstopping after this episode (Ctrl-C again to quit at once)", flush=True)

    previous = {}
    try:
        for sig in (signal.SIGINT, signal.SIGTERM):
            previous[sig] = signal.getsignal(sig)
            signal.signal(sig, handler)
    except ValueError:  # not the main thread: signals keep their default behaviour
        previous = {}
    try:
        yield stop
    finally:
        for sig, old in previous.items():
            signal.signal(sig, old)


def progress_bar(total: int, initial: int, enabled: bool) -> Any:
    """The run's bar over its ``total`` steps, from ``initial``; silent unless ``enabled``."""
    from tqdm import tqdm

    return tqdm(
        total=total,
        initial=initial,
        disable=not enabled,
        unit="step",
        dynamic_ncols=True,
        # The average rate: the bar moves fast while an episode is collected and waits for its
        # updates, and a moving average of those bursts would promise too early an end.
        smoothing=0.0,
    )


def bar_postfix(row: dict[str, Any], last_eval: dict[str, float]) -> dict[str, Any]:
    """The bar's fields after an episode: steps/s, proxy return, the last evaluation."""
    out: dict[str, Any] = {"sps": row.get("steps_per_s"), "proxy": row.get("proxy_return")}
    if "eval_score_norm" in last_eval:
        out["eval"] = last_eval["eval_score_norm"]
    elif "eval_score" in last_eval:
        out["eval"] = last_eval["eval_score"]
    return out
