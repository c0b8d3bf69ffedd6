"""`ilfo train`'s progress bar: it moves within an episode, and its fields are explained."""

from __future__ import annotations

import pytest

from ilfo.training import TrainConfig, Trainer
from tiny_run import TINY_RUN


class _Bar:
    """A progress bar that records where each of its moves left it."""

    def __init__(self, total: int, initial: int, enabled: bool) -> None:
        self.n = initial
        self.positions: list[int] = []

    def update(self, steps: int) -> None:
        self.n += steps
        self.positions.append(self.n)

    def set_postfix(self, postfix: dict, refresh: bool = True) -> None:
        pass

    def close(self) -> None:
        pass


@pytest.mark.integration
def test_the_bar_moves_within_an_episode_and_ends_at_the_steps(tmp_path, monkeypatch):
    bars: list[_Bar] = []

    def make_bar(total: int, initial: int, enabled: bool) -> _Bar:
        bars.append(_Bar(total, initial, enabled))
        return bars[-1]

    monkeypatch.setattr("ilfo.training.loop.progress_bar", make_bar)
    # 200 random steps, two 100-step episodes: nothing to compile but the evaluation's policy.
    config = TrainConfig(**{**TINY_RUN, "steps": 200})
    Trainer(config, tmp_path / "run").train()
    (bar,) = bars
    assert bar.n == 200
    within = [n for n in bar.positions if n % 100]  # not at an episode's end
    assert within[0] == 10  # a tenth of the first (100-step) episode in
    assert len(within) == 2 * 9 and within == sorted(within)  # nine moves in each episode


def test_the_start_summary_and_the_help_say_what_proxy_is(capsys):
    from pathlib import Path

    from ilfo.cli import main
    from ilfo.cli.train import start_summary

    proxy = "proxy: the imitation reward's return of the last training episode"
    summary = start_summary(TrainConfig(), Path("runs/r"), None, progress=True)
    assert proxy in summary
    assert "proxy" not in start_summary(TrainConfig(), Path("runs/r"), None)  # no bar, no key
    with pytest.raises(SystemExit):
        main(["train", "--help"])
    assert proxy in " ".join(capsys.readouterr().out.split())
