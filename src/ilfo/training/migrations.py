"""Run records of every format ilfo has written, read as today's: the one home of that history.

What a run writes carries its format: ``config.json`` its ``"format"`` (``CONFIG_FORMAT``; an
expert's ``expert.json`` and a sweep's manifest hold configs in the same format), a
checkpoint's ``state.json`` its ``"schema"`` (``CHECKPOINT_FORMAT``). Records written before
the numbers are format 0 (``UNVERSIONED``). Reading a record upgrades it here, one step at a
time from its format to today's, so the rest of ilfo knows only today's format; a record of
today's format goes through no step. Each step is a function from format N to N + 1 whose
docstring says what changed (several changes came before config.json had a number: its step
from format 0 makes each, told apart by what the record holds).

A field added with a default that keeps what older runs did needs no step (an older record
reads back with the default); a renamed key or file, or a changed meaning or default, does,
with a new format number. Resuming an older run brings its directory to today's format
(``upgrade_run_dir``): the trainer then writes it as any run of today's.
"""

from __future__ import annotations

import dataclasses
import functools
import warnings
from collections.abc import Callable, Collection, Mapping
from pathlib import Path
from typing import Any

from ilfo.algos import AGENT_PARTS, ALGOS
from ilfo.files import read_settings_file, write_json_atomic
from ilfo.training.run_dir import (
    BEST_POLICY_FILE,
    CHECKPOINTS_DIR,
    CONFIG_FILE,
    DEMOS_RECORD_FILE,
    METRICS_FILE,
    read_json_object,
)

UNVERSIONED = 0
"""The format of records written before they carried one."""
FORMAT_KEY = "format"
"""config.json's key for its format (a checkpoint's state.json has ``CHECKPOINT_KEY``)."""
CONFIG_FORMAT = 2
"""config.json's format today: a ``TrainConfig``'s fields, every setting resolved as the run
used it (``TrainConfig.resolved``); since format 2 TD7's records say whether it evaluated
with policy checkpoints."""
CHECKPOINT_KEY = "schema"
CHECKPOINT_FORMAT = 2
"""A checkpoint's format today (``checkpoint.save_checkpoint``): state.json holds the loop's
state as ``loop`` (``checkpoint.LoopState``: counters, evaluations, the file of its
random-phase states) and the reward's as ``reward_state`` (its values and the file of its
arrays, or null for the task reward)."""

Record = dict[str, Any]


# ------------------------------------------------------------------------------ configs
def _contact_forces_observed(record: Record) -> Record:
    """``contact_forces`` came on 2026-12-02: before, every run observed the contact forces (a
    record without the key reads as True)."""
    return {"contact_forces": True, **record}


_UNRESOLVED_EPISODES = {"pwil-td3": True}
"""The episodes (``fixed_horizon``) each algo trained on before 2026-12-05, where its default
has changed since: PWIL-(s) ran on the fixed horizon, and trains on standard episodes now.
(f-IRL's changed too, but its records of either default say None and cannot be told apart.)"""


def _episodes_resolved(record: Record) -> Record:
    """Since 2026-12-05 config.json records the episodes resolved (``fixed_horizon`` True or
    False); before, None meant the algo's default of the time (``_UNRESOLVED_EPISODES``), so
    that an old run resumes and reports on the episodes it ran."""
    if record.get("fixed_horizon") is not None:
        return record
    ran = _UNRESOLVED_EPISODES.get(str(record.get("algo")))
    return record if ran is None else {**record, "fixed_horizon": ran}


def _task_reward_demos_dropped(record: Record) -> Record:
    """Since 2026-12-07 demos are refused for a task-reward algo; before, its records listed
    them (ignored): they read back without them."""
    recipe = ALGOS.get(str(record.get("algo")))
    if recipe is None or recipe.imitation:
        return record
    return {key: value for key, value in record.items() if key != "demos"}


def _run_config_0_to_1(record: Record) -> Record:
    """config.json carries its format (format 1), and older records read as the runs ran:
    with the contact forces they observed, the episodes they trained on and no task-reward
    demos (``_contact_forces_observed``, ``_episodes_resolved``,
    ``_task_reward_demos_dropped``)."""
    return _task_reward_demos_dropped(_episodes_resolved(_contact_forces_observed(record)))


def _sweep_run_config_0_to_1(record: Record) -> Record:
    """A sweep manifest's run config carries its format (format 1); older ones read with the
    contact forces their runs observed and no task-reward demos. Unlike a run's config.json a
    manifest holds its settings unresolved: ``fixed_horizon`` None is the algo's default."""
    return _task_reward_demos_dropped(_contact_forces_observed(record))


def _config_1_to_2(record: Record) -> Record:
    """Format 2 (2026-12-07): TD7 evaluates with its policy checkpoints by default
    (``TD7Config.policy_checkpoints``); before, it evaluated the policy as trained, so a TD7
    record without the setting reads with it off. A sweep manifest's TD7 config left to the
    defaults (None) is resolved to its preset's, with them off: the sweep's runs not yet
    started train as its others did."""
    recipe = ALGOS.get(str(record.get("algo")))
    if recipe is None or recipe.agent != "td7":
        return record
    td7 = record.get("td7")
    if td7 is None:
        td7 = dataclasses.asdict(AGENT_PARTS["td7"].default(str(record.get("preset", "paper"))))
        td7.pop("policy_checkpoints")
    if not isinstance(td7, Mapping) or "policy_checkpoints" in td7:
        return record  # a damaged record: TrainConfig names its fault
    return {**record, "td7": {**td7, "policy_checkpoints": False}}


_RUN_CONFIG_STEPS: dict[int, Callable[[Record], Record]] = {
    UNVERSIONED: _run_config_0_to_1,
    1: _config_1_to_2,
}
_SWEEP_RUN_CONFIG_STEPS: dict[int, Callable[[Record], Record]] = {
    UNVERSIONED: _sweep_run_config_0_to_1,
    1: _config_1_to_2,
}


def config_record(settings: Mapping[str, Any]) -> Record:
    """What ilfo writes of a config (``dataclasses.asdict`` of a ``TrainConfig``, or today's
    settings read back): its fields with today's ``CONFIG_FORMAT``."""
    return {FORMAT_KEY: CONFIG_FORMAT, **{k: v for k, v in settings.items() if k != FORMAT_KEY}}


def upgrade_run_config(record: Mapping[str, Any], source: str | Path) -> Record:
    """A run's recorded config (config.json, an expert's ``train_config``) of any format as
    today's settings (without the format key, for ``config.config_from_dict``); a ValueError
    names ``source`` for a format this ilfo does not know."""
    return _upgraded(record, FORMAT_KEY, CONFIG_FORMAT, _RUN_CONFIG_STEPS, source)


def upgrade_sweep_run_config(record: Mapping[str, Any], source: str | Path) -> Record:
    """A sweep manifest's run config of any format as today's settings (see
    ``upgrade_run_config``)."""
    return _upgraded(record, FORMAT_KEY, CONFIG_FORMAT, _SWEEP_RUN_CONFIG_STEPS, source)


def _upgraded(
    record: Mapping[str, Any],
    key: str,
    today: int,
    steps: Mapping[int, Callable[[Record], Record]],
    source: str | Path,
) -> Record:
    """``record`` through ``steps`` from its format (``record[key]``) to ``today``, without the
    key."""
    version = record.get(key, UNVERSIONED)
    if type(version) is not int or not (version == today or version in steps):
        raise ValueError(
            f"{source}: {key} {record.get(key)!r}, not one this ilfo reads (formats up to {today}; "
            "written by a newer ilfo?)"
        )
    upgraded = {k: v for k, v in record.items() if k != key}
    while version != today:
        upgraded, version = steps[version](upgraded), version + 1
    return upgraded


def read_run_config(run_dir: str | Path) -> Record:
    """A run directory's config.json as today's settings (``upgrade_run_config``), with a clear
    error for a missing or damaged one (field names and values are checked by ``TrainConfig``:
    see ``config.config_from_dict``)."""
    path = Path(run_dir) / CONFIG_FILE
    if not path.is_file():
        raise FileNotFoundError(f"{run_dir} is not a run directory (no {CONFIG_FILE})")
    return upgrade_run_config(read_json_object(path), path)


def read_settings(path: str | Path) -> Record:
    """A settings file (``files.read_settings_file``), read as the run record it is where it is
    one (a config.json beside its run's metrics.csv, or any file with a format key): then as
    ``read_run_config`` reads it, so that ``--config RUN/config.json`` repeats the run as it
    ran even where its algo's defaults have changed since."""
    path = Path(path)
    settings = read_settings_file(path)
    beside_its_run = path.name == CONFIG_FILE and (path.parent / METRICS_FILE).is_file()
    if beside_its_run or FORMAT_KEY in settings:
        return upgrade_run_config(settings, path)
    return settings


# -------------------------------------------------------------------------- checkpoints
def _checkpoint_1_to_2(state: Record, files: Collection[str]) -> Record:
    """Format 2 gathers the loop's state under ``loop`` and names the files of arrays (the
    random-phase states, the reward's) in state.json. Format 1 (2026-11-22 on) held the
    loop's counters at the top, and its files were found by their names; before 2026-12-01 it
    named the reward's state ``rewarder_rng`` (OOPS's generator; null for other rewards) and
    its arrays ``rewarder_potentials.npz`` (OOPS's warm starts); before 2026-12-02 it had no
    ``refill_until`` (0), and in its first days no ``best_eval`` (none yet)."""
    if "reward_state" in state:
        values = state["reward_state"]
    else:
        values = None if state["rewarder_rng"] is None else {"rng": state["rewarder_rng"]}
    arrays = next((f for f in ("reward_arrays.npz", "rewarder_potentials.npz") if f in files), None)
    reward = None
    if values is not None or arrays is not None:
        reward = {"values": values or {}, "arrays": arrays}
    loop = {
        "step": state["step"],
        "episode": state["episode"],
        "elapsed": state["elapsed"],
        "last_eval": state["last_eval"],
        "best_eval": state.get("best_eval", {}),
        "refill_until": state.get("refill_until", 0),
        "random_states": "random_states.npz" if "random_states.npz" in files else None,
    }
    return {"loop": loop, "reward_state": reward}


_CHECKPOINT_STEPS: dict[int, Callable[..., Record]] = {1: _checkpoint_1_to_2}
"""From each older format, the step to the next; each takes the state and the names of the
checkpoint's files."""


def upgrade_checkpoint_state(
    state: Mapping[str, Any], files: Collection[str], source: str | Path
) -> Record:
    """A checkpoint's state.json of any format as today's (``CHECKPOINT_FORMAT``, without the
    format key); ``files``: the names of the files in its directory. A ValueError names
    ``source`` for a format this ilfo does not know; a KeyError or TypeError means a damaged
    state."""
    steps = {v: functools.partial(step, files=files) for v, step in _CHECKPOINT_STEPS.items()}
    return _upgraded(state, CHECKPOINT_KEY, CHECKPOINT_FORMAT, steps, source)


def keep_best_policy_of_older_checkpoint(
    best_step: int, best_eval: Mapping[str, float], checkpoint: Path | None, run_dir: Path
) -> None:
    """Resuming from a checkpoint with a best evaluation but no copy of its best policy: one
    written before 2026-12-05, when checkpoints began keeping it. The run's best policy (of
    step ``best_step``) stays; where it is not the checkpoint's (``best_eval``), a warning: a
    continuation that is not exact may not reach it again."""
    if best_step != best_eval.get("step"):
        warnings.warn(
            f"{run_dir / BEST_POLICY_FILE} is from step {best_step}, after checkpoint "
            f"{checkpoint}, which holds no copy of its own best (step "
            f"{int(best_eval['step'])}; written by an earlier ilfo): it stays, though a "
            "continuation that is not exact may not reach it again",
            stacklevel=4,
        )


# ------------------------------------------------------------------------ run directories
_OBSOLETE_CHECKPOINT_FILES = ("latest", ".latest.tmp")
"""The pointer to the newest checkpoint (and its temporary copy) that runs kept before
2026-12-01, when checkpoints began to be found by scanning: stale once a run continues."""


def upgrade_run_dir(run_dir: Path, demos_record: Mapping[str, Any] | None) -> None:
    """Bring an older run directory to today's format as a trainer resumes it (it holds the
    run's lock): where it has no ``demos.json`` (runs before 2026-12-04), ``demos_record`` (the
    demos it resumes on, from the step it resumes at; None for the task reward); the
    checkpoints' pointer of runs before 2026-12-01 removed; and config.json rewritten in
    today's format, last, so that a kill midway leaves a run this upgrades again. A run of
    today's format is left as it is. Its checkpoints stay as they are: each says its format,
    and the next the run writes is today's."""
    path = run_dir / CONFIG_FILE
    record = read_json_object(path)
    if record.get(FORMAT_KEY, UNVERSIONED) == CONFIG_FORMAT:
        return
    settings = upgrade_run_config(record, path)
    if demos_record is not None and not (run_dir / DEMOS_RECORD_FILE).is_file():
        write_json_atomic(run_dir / DEMOS_RECORD_FILE, dict(demos_record))
    for name in _OBSOLETE_CHECKPOINT_FILES:
        (run_dir / CHECKPOINTS_DIR / name).unlink(missing_ok=True)
    write_json_atomic(path, config_record(settings))
