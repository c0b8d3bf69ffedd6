"""Sweeps: a manifest of runs in a sweep directory, and the state of each run read off the disk.

A sweep is the product env x algo x variant x num_demos x seed of one base config. Its
directory holds::

    sweep.json            the spec as given and every run's full config (the manifest)
    runs/NAME/            each run's ordinary run directory (``ilfo train``'s layout)
    attempts/NAME.jsonl   one line per launch, start and end of the run's workers (host, pid,
                          CPUs, threads, exit, error: ``attempts``)
    logs/NAME.log         the worker's output

Nothing else records progress: a run is *done* when its final policy is written and its newest
checkpoint reached the run's steps, *running* while a process holds its run lock,
*unresumable* when it has no complete checkpoint but holds what only a run past its first one
writes (its final policy, metrics rows after that checkpoint's: its checkpoints were removed;
``run_dir.results_past_first_checkpoint``), which is never trained again (that would delete
them), *failed* when it ended with an error more often than the sweep allows, else *pending*
(with the steps its metrics reached). So a sweep can be killed at any moment and started
again: finished runs are skipped, interrupted ones resume from their checkpoints, and each run
is trained exactly once.
"""

from __future__ import annotations

import dataclasses
import fnmatch
import json
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

from ilfo.experiments.attempts import read_attempts
from ilfo.files import check_new_copy_dir, read_settings_file, write_json_atomic
from ilfo.ranges import check_fields, count, declared, rng_seed

MANIFEST_FILE = "sweep.json"
RUNS_DIR = "runs"
ATTEMPTS_DIR = "attempts"
LOGS_DIR = "logs"
LAUNCH_LOCK = ".launch.lock"
"""Held by a ``sweep run`` process while it chooses CPUs for a worker and starts it
(``backends.LocalBackend``), so that two processes never choose the same ones."""
SWEEP_PARTS = (RUNS_DIR, ATTEMPTS_DIR, LOGS_DIR)
"""The folders a sweep directory holds beside its manifest."""
AXES = ("env", "algo", "num_demos", "seed")
"""The axes of a sweep, besides its named variants."""

RunState = Literal["done", "running", "unresumable", "failed", "pending"]
RUN_STATES: tuple[RunState, ...] = ("done", "running", "unresumable", "failed", "pending")


@dataclass(frozen=True)
class SweepSpec:
    """What a sweep runs: every combination of the axes, each with the base ``config``."""

    env: tuple[str, ...] = declared(("Hopper-v5",), min_items=1)
    """Environment ids."""
    algo: tuple[str, ...] = declared(("oops-td3",), min_items=1)
    """Algorithms (``ilfo.algos``)."""
    num_demos: tuple[int, ...] = count((1,), min_items=1)
    """Numbers of demos imitated."""
    seed: tuple[int, ...] = rng_seed((0,), min_items=1)
    """Seeds."""
    config: Mapping[str, Any] = field(default_factory=dict)
    """Settings of every run, as ``ilfo train``'s flags or a config file give them
    (``TrainConfig`` fields; a part's dict, e.g. ``{"td3": {"batch_size": 256}}``, changes
    single fields of its default). A part's settings apply to the runs whose algo uses it."""
    variants: Mapping[str, Mapping[str, Any]] = field(default_factory=dict)
    """Named changes of ``config`` (e.g. ``{"lambda0.1": {"oops": {"reg": 0.1}}}``), each
    a further axis value; none: one unnamed variant, the base config."""
    retries: int = count(2, low=0)
    """How many times a run that ended with an error is started again."""

    def __post_init__(self) -> None:
        for name in AXES:  # one value alone is that axis's only value
            if isinstance(getattr(self, name), (str, int)):
                object.__setattr__(self, name, (getattr(self, name),))
        check_fields(self)  # types and ranges, from the fields' declarations (ilfo.ranges)
        for name in AXES:
            values = getattr(self, name)
            if len(set(values)) != len(values):
                raise ValueError(f"sweep {name} lists a value twice: {list(values)}")
        # As JSON has them (lists for tuples), so that a spec equals its manifest's copy.
        try:
            object.__setattr__(self, "config", json.loads(json.dumps(dict(self.config))))
            variants = {k: dict(v) for k, v in dict(self.variants).items()}
            object.__setattr__(self, "variants", json.loads(json.dumps(variants)))
        except (TypeError, ValueError) as err:
            raise ValueError(f"sweep config and variants must be JSON data: {err}") from None
        axis_flags = {
            "env": "--env",
            "algo": "--algo",
            "num_demos": "--num-demos",
            "seed": "--seeds",
        }
        for key in self.config:
            if key in AXES or key == "out":
                where = f"its axis ({axis_flags[key]})" if key in AXES else "the sweep directory"
                raise ValueError(f"sweep config cannot set {key!r}: {where} sets it")
        for name, change in self.variants.items():
            if not name or "__" in name or "/" in name:
                raise ValueError(f"variant name {name!r} must be non-empty, without '__' or '/'")
            bad = [key for key in change if key in AXES or key == "out"]
            if bad:
                raise ValueError(f"variant {name!r} cannot set {', '.join(bad)}")

    def to_dict(self) -> dict[str, Any]:
        """The spec as JSON-ready data (what ``from_dict`` reads back)."""
        out = dataclasses.asdict(self)
        return {k: list(v) if isinstance(v, tuple) else v for k, v in out.items()}

    @classmethod
    def from_dict(cls, raw: Mapping[str, Any], source: str | Path = "sweep spec") -> SweepSpec:
        """A spec from a dict (a spec file); ``seeds``/``envs``/``algos`` are accepted for
        the axes, a seed range as ``"0-4"``, and ``config`` may name a settings file."""
        aliases = {"envs": "env", "algos": "algo", "seeds": "seed"}
        values = {aliases.get(k, k): v for k, v in raw.items()}
        known = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(values) - known)
        if unknown:
            raise ValueError(
                f"{source}: unknown sweep setting(s) {', '.join(map(repr, unknown))}; "
                f"known: {', '.join(sorted(known))}"
            )
        if isinstance(values.get("seed"), str):
            values["seed"] = parse_seeds([values["seed"]])
        if isinstance(values.get("config"), str):
            from ilfo.training import settings_for_new_runs

            # A finished run's config.json repeats that run: the sweep sets its axes and out.
            values["config"] = settings_for_new_runs(
                read_settings_file(values["config"]), (*AXES, "out")
            )
        try:
            return cls(**values)
        except (TypeError, ValueError) as err:
            raise ValueError(f"{source}: {err}") from None


def parse_seeds(items: Sequence[str | int]) -> tuple[int, ...]:
    """Seeds from ``["0-4"]``, ``["0", "3", "7"]`` or a mix (ranges include both ends)."""
    seeds: list[int] = []
    for item in items:
        text = str(item).strip()
        low, dash, high = text.partition("-")
        try:
            if dash and low:
                first, last = int(low), int(high)
            else:
                first = last = int(text)
        except ValueError:
            raise ValueError(f"seeds: {text!r} is neither a seed nor a range like 0-4") from None
        if first < 0:
            raise ValueError(f"seeds: {text!r}: seeds are >= 0")
        if last < first:
            raise ValueError(f"seeds: {text!r} is a reversed range (write {last}-{first})")
        seeds.extend(range(first, last + 1))
    return tuple(seeds)


@dataclass(frozen=True)
class SweepRun:
    """One run of a sweep: its name (``env__algo[__variant]__demosN__seed``) and full config."""

    name: str
    config: dict[str, Any]
    """The run's resolved ``TrainConfig`` as config.json records it."""
    variant: str | None = None

    @property
    def steps(self) -> int:
        return int(self.config["steps"])


def run_name_of(env: str, algo: str, variant: str | None, num_demos: int, seed: int) -> str:
    """A sweep run's directory name, CleanRL's env__algo__seed with the other axes inside."""
    middle = f"__{variant}" if variant else ""
    return f"{env}__{algo}{middle}__demos{num_demos}__{seed}"


def expand(spec: SweepSpec) -> list[SweepRun]:
    """Every run of the spec, each config built and checked now (an error names the run), in
    seed-major order so that a partly done sweep covers every cell with its first seeds."""
    from ilfo.algos import PART_CONFIGS, recipe
    from ilfo.envs import CONTACT_FORCE_DIMS
    from ilfo.envs.make import env_spec
    from ilfo.training import config_from_settings

    for env in spec.env:  # a misspelt id fails now, not in every one of its runs
        env_spec(env)

    variants: list[tuple[str | None, Mapping[str, Any]]] = list(spec.variants.items()) or [
        (None, {})
    ]
    parts_given = {k for k in spec.config if k in PART_CONFIGS}
    parts_used: set[str] = set()
    runs = []
    for seed in spec.seed:
        for env in spec.env:
            for algo in spec.algo:
                algo_parts = {recipe(algo).agent, recipe(algo).reward}
                for variant, change in variants:
                    for num_demos in spec.num_demos:
                        name = run_name_of(env, algo, variant, num_demos, seed)
                        settings = merge_settings(spec.config, change)
                        # A part's settings apply where the algo uses that part (a sweep over
                        # oops-td3 and pwil-td3 can set OOPS's lambda).
                        unused = [k for k in settings if k in PART_CONFIGS and k not in algo_parts]
                        parts_used |= {k for k in settings if k in PART_CONFIGS} - set(unused)
                        settings = {k: v for k, v in settings.items() if k not in unused}
                        # Likewise dropping the contact forces, where the env observes them.
                        if env not in CONTACT_FORCE_DIMS:
                            settings.pop("contact_forces", None)
                        if not recipe(algo).imitation:  # and the demos, for the task reward
                            settings.pop("demos", None)
                        settings.update(env=env, algo=algo, num_demos=num_demos, seed=seed)
                        config = config_from_settings(settings, f"sweep run {name}")
                        runs.append(SweepRun(name, _config_record(config), variant))
    sets_contact_forces = any(
        settings.get("contact_forces") is not None
        for settings in (spec.config, *(change for _, change in variants))
    )
    if sets_contact_forces and not set(spec.env) & set(CONTACT_FORCE_DIMS):
        raise ValueError(
            f"sweep config sets contact_forces, which none of its envs observe "
            f"({', '.join(spec.env)}; only {', '.join(CONTACT_FORCE_DIMS)} do)"
        )
    unused_parts = sorted(parts_given - parts_used)
    if unused_parts:
        raise ValueError(
            f"sweep config sets {', '.join(unused_parts)}, which no algo of the sweep uses "
            f"({', '.join(spec.algo)})"
        )
    return runs


def merge_settings(base: Mapping[str, Any], change: Mapping[str, Any]) -> dict[str, Any]:
    """``base`` with ``change`` on top; a part's dicts merge field by field."""
    out = dict(base)
    for key, value in change.items():
        if isinstance(value, Mapping) and isinstance(out.get(key), Mapping):
            out[key] = {**out[key], **value}
        else:
            out[key] = value
    return out


def _config_record(config: Any) -> dict[str, Any]:
    """A TrainConfig as JSON-ready data (tuples as lists, as config.json has them)."""
    return json.loads(json.dumps(dataclasses.asdict(config)))


@dataclass(frozen=True)
class Sweep:
    """A sweep directory and its manifest."""

    root: Path
    spec: SweepSpec
    runs: tuple[SweepRun, ...]

    def run(self, name: str) -> SweepRun:
        for run in self.runs:
            if run.name == name:
                return run
        raise KeyError(f"{self.root} has no run named {name!r}")

    def run_dir(self, name: str) -> Path:
        return self.root / RUNS_DIR / name

    def attempts_file(self, name: str) -> Path:
        return self.root / ATTEMPTS_DIR / f"{name}.jsonl"

    def log_file(self, name: str) -> Path:
        return self.root / LOGS_DIR / f"{name}.log"

    def statuses(self) -> list[RunStatus]:
        return [run_status(self, run) for run in self.runs]


def select_runs(
    names: Sequence[str], only: Sequence[str] = (), skip: Sequence[str] = ()
) -> tuple[str, ...]:
    """The run names that match a pattern of ``only`` (all when it is empty) and none of
    ``skip``, in their order; patterns are shell globs (``"Ant-v5__*"``, ``"*__pwil-td3__*"``).
    A pattern that matches no run is an error: a misspelt one would otherwise silently run
    everything or nothing."""
    for pattern in (*only, *skip):
        if not fnmatch.filter(names, pattern):
            example = f", e.g. {names[0]!r}" if names else ""
            raise ValueError(
                f"no run matches {pattern!r} (runs are named ENV__ALGO__demosN__SEED{example})"
            )

    def matches(name: str, patterns: Sequence[str]) -> bool:
        return any(fnmatch.fnmatchcase(name, pattern) for pattern in patterns)

    return tuple(
        name for name in names if (not only or matches(name, only)) and not matches(name, skip)
    )


def sweep_labels(sweeps: Sequence[Sweep]) -> list[str]:
    """Short names for several sweeps in listings and messages (``LABEL/RUN``): each
    directory's own name, or the path as given where two share a name (``exp1/sweep``,
    ``exp2/sweep``)."""
    names = [sweep.root.resolve().name for sweep in sweeps]
    return [
        name if names.count(name) == 1 else str(sweep.root)
        for name, sweep in zip(names, sweeps, strict=True)
    ]


def create_sweep(root: str | Path, spec: SweepSpec) -> Sweep:
    """Write the manifest of ``spec`` to ``root`` (made if missing). A directory that holds a
    sweep already is reused only for the same spec, whose ``retries`` alone may change
    (``open_sweep`` continues it as it is); a file, or a directory that holds anything but a
    sweep's parts, is refused."""
    root = Path(root)
    runs = tuple(expand(spec))
    manifest = root / MANIFEST_FILE
    existing = matching_sweep(root, spec)
    if existing is not None:
        if existing.spec.retries != spec.retries:  # the one setting a sweep may change
            raw = read_settings_file(manifest)
            raw["spec"]["retries"] = spec.retries
            write_json_atomic(manifest, raw)
            existing = Sweep(root, spec, existing.runs)
        return existing
    if root.exists() and not root.is_dir():
        raise ValueError(f"{root} is a file, not a sweep directory")
    # The sweep's own folders, lock or a manifest's temporary file: a sweep made before (whose
    # manifest was lost) or being made by another process now (its manifest may have
    # appeared since it was looked for); anything else is someone's folder.
    others = sorted(p.name for p in root.iterdir() if not _ours(p.name)) if root.exists() else []
    if others:
        raise ValueError(
            f"{root} holds other files and no sweep ({', '.join(others[:3])}"
            f"{', ...' if len(others) > 3 else ''}): choose a new or empty directory"
        )
    root.mkdir(parents=True, exist_ok=True)
    for sub in SWEEP_PARTS:
        (root / sub).mkdir(exist_ok=True)
    matching_sweep(root, spec)  # one another process made meanwhile must be this sweep
    from ilfo.training.migrations import config_record

    record = {
        "spec": spec.to_dict(),
        "runs": [
            {"name": r.name, "variant": r.variant, "config": config_record(r.config)} for r in runs
        ],
        "created": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
    }
    write_json_atomic(manifest, record)
    return Sweep(root, spec, runs)


def _ours(name: str) -> bool:
    """Whether a name in a sweep directory is one that a sweep, or its making, puts there."""
    temporary = name.startswith(f".{MANIFEST_FILE}.") and name.endswith(".tmp")
    return name in (*SWEEP_PARTS, MANIFEST_FILE, LAUNCH_LOCK) or temporary


def matching_sweep(root: str | Path, spec: SweepSpec) -> Sweep | None:
    """The sweep already in ``root`` if its spec is ``spec`` (``retries`` aside), None if
    ``root`` holds no sweep; a ValueError if it holds another one."""
    root = Path(root)
    if not (root / MANIFEST_FILE).exists():
        return None
    existing = open_sweep(root)
    if dataclasses.replace(existing.spec, retries=spec.retries) != spec:
        raise ValueError(
            f"{root} holds another sweep (its spec differs from this one); continue it "
            "with `ilfo sweep run` and no spec, or choose a new directory"
        )
    return existing


def open_sweep(root: str | Path) -> Sweep:
    """The sweep in ``root``, read from its manifest (clear errors for what is not one); its
    runs' configs in today's format (``training.migrations``)."""
    from ilfo.training.migrations import upgrade_sweep_run_config

    root = Path(root)
    path = root / MANIFEST_FILE
    if not path.is_file():
        raise FileNotFoundError(f"{root} is not a sweep directory (no {MANIFEST_FILE})")
    raw = read_settings_file(path)
    try:
        spec = SweepSpec.from_dict(raw["spec"], path)
        runs = tuple(SweepRun(r["name"], r["config"], r.get("variant")) for r in raw["runs"])
    except (KeyError, TypeError, AttributeError) as err:
        raise ValueError(f"{path} is not a sweep manifest ({err!r} missing or wrong)") from None
    for run in runs:  # what the scheduler reads of each run before its worker checks it
        steps = run.config.get("steps") if isinstance(run.config, dict) else None
        if type(steps) is not int or not isinstance(run.name, str):
            raise ValueError(f"{path}: run {run.name!r} has steps {steps!r}, not a whole number")
    runs = tuple(
        SweepRun(r.name, upgrade_sweep_run_config(r.config, f"{path} (run {r.name})"), r.variant)
        for r in runs
    )
    return Sweep(root, spec, runs)


def snapshot_sweep(root: str | Path, out: str | Path) -> dict[str, str]:
    """A copy of a stopped sweep small enough to keep in git or move between machines: its
    manifest, attempts and logs, and each run that has a checkpoint as ``snapshot_run`` copies
    it (no replay buffer; an on-policy run's pending batch is kept). ``ilfo sweep run OUT``
    continues it: finished runs stay done, interrupted ones resume from their checkpoint (the
    buffer refilled by ``start_steps`` steps of the current policy, so not the exact
    continuation; on-policy runs exactly), and runs without a checkpoint start afresh.

    Returns what became of each run: ``done``, ``checkpoint at step N``, ``unresumable`` (its
    results copied without a checkpoint, so that the copy reads as the sweep does and never
    trains it again) or ``left out (no checkpoint)``. Raises FileExistsError where ``out``
    exists, and ValueError where it lies inside the sweep or while any run of the sweep is
    running (stop the sweep first: Ctrl-C checkpoints every run)."""
    import shutil

    from ilfo.training.checkpoint import snapshot_run
    from ilfo.training.run_dir import checkpoint_steps, copy_results

    sweep, out = open_sweep(root), Path(out)
    check_new_copy_dir(sweep.root, out)
    statuses = sweep.statuses()
    running = [s.name for s in statuses if s.state == "running"]
    if running:
        raise ValueError(
            f"runs of {sweep.root} are running ({', '.join(running)}): stop the sweep first "
            "(Ctrl-C checkpoints every run)"
        )
    tmp = out.with_name(f".{out.name}.tmp")
    shutil.rmtree(tmp, ignore_errors=True)
    try:
        tmp.mkdir(parents=True)
        shutil.copy2(sweep.root / MANIFEST_FILE, tmp / MANIFEST_FILE)
        for sub in (ATTEMPTS_DIR, LOGS_DIR):
            if (sweep.root / sub).is_dir():
                shutil.copytree(sweep.root / sub, tmp / sub)
            else:
                (tmp / sub).mkdir()
        (tmp / RUNS_DIR).mkdir()
        kept = {}
        for status in statuses:
            checkpoints = checkpoint_steps(sweep.run_dir(status.name))
            if status.state == "unresumable":
                (tmp / RUNS_DIR / status.name).mkdir()
                copy_results(sweep.run_dir(status.name), tmp / RUNS_DIR / status.name)
                kept[status.name] = "unresumable (results, no checkpoint)"
                continue
            if not checkpoints:
                kept[status.name] = "left out (no checkpoint)"
                continue
            # Refused (ValueError) if a run was started again since the check above.
            snapshot_run(sweep.run_dir(status.name), tmp / RUNS_DIR / status.name)
            kept[status.name] = (
                "done" if status.state == "done" else f"checkpoint at step {checkpoints[-1][0]}"
            )
        tmp.rename(out)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)  # no half-written copy left beside ``out``
        raise
    return kept


# ------------------------------------------------------------------------------ run states
@dataclass(frozen=True)
class RunStatus:
    """Where one run of a sweep stands, as read off its files."""

    name: str
    state: RunState
    step: int
    """Environment steps its metrics reached (0 before the first episode)."""
    steps: int
    """Its budget."""
    failures: int
    """How many of its attempts ended with an error (not counting interruptions)."""
    error: str | None = None
    """The last failure's message; for an unresumable run, what it holds and how to go on."""
    steps_per_s: float | None = None
    """A running run's recent speed (its last episodes, evaluations included); None else."""

    @property
    def hours_left(self) -> float | None:
        """A running run's remaining steps at its recent speed, in hours; None else."""
        if not self.steps_per_s:
            return None
        return (self.steps - self.step) / self.steps_per_s / 3600


def run_status(sweep: Sweep, run: SweepRun) -> RunStatus:
    """The run's state (see the module's docstring)."""
    from ilfo.training.run_dir import FINAL_POLICY_FILE, checkpoint_steps

    run_dir = sweep.run_dir(run.name)
    events = read_attempts(sweep, run.name)
    resets = [i for i, e in enumerate(events) if e.get("event") == "reset"]
    events = events[resets[-1] + 1 :] if resets else events  # failures before a reset forgiven
    ended = [e for e in events if e.get("event") == "end"]
    failed = [e for e in ended if e.get("status") in ("error", "killed")]
    error = failed[-1].get("error") if failed else None
    checkpoints = checkpoint_steps(run_dir)
    step = max(_metrics_step(run_dir), checkpoints[-1][0] if checkpoints else 0)
    if (run_dir / FINAL_POLICY_FILE).is_file() and checkpoints and checkpoints[-1][0] >= run.steps:
        state: RunState = "done"
    elif _locked(run_dir):
        state = "running"
    elif (results := _results_past_first_checkpoint(sweep, run, checkpoints)) is not None:
        state = "unresumable"
        error = (
            f"{run_dir} has no complete checkpoint but holds the results of a run past its "
            f"first one ({results}): not trained again, which would delete them; to train it "
            "afresh, move the directory away"
        )
    elif len(failed) > sweep.spec.retries:
        state = "failed"
    else:
        state = "pending"
    rate = _metrics_rate(run_dir) if state == "running" else None
    return RunStatus(run.name, state, min(step, run.steps), run.steps, len(failed), error, rate)


def _results_past_first_checkpoint(
    sweep: Sweep, run: SweepRun, checkpoints: Sequence[tuple[int, Path]]
) -> str | None:
    """``run_dir.results_past_first_checkpoint`` of a run with no checkpoint at all, by its
    config in the manifest; None where it has one (``checkpoints``, its complete ones), or a
    damaged one, which its worker's resume refuses with the repair to make."""
    from ilfo.training import config_from_dict
    from ilfo.training.run_dir import damaged_checkpoints, results_past_first_checkpoint

    if checkpoints or damaged_checkpoints(sweep.run_dir(run.name)):
        return None
    config = config_from_dict(run.config, f"{sweep.root / MANIFEST_FILE} (run {run.name})")
    return results_past_first_checkpoint(sweep.run_dir(run.name), config)


def _locked(run_dir: Path) -> bool:
    """Whether a live process holds the run's lock now."""
    from ilfo.training.run_dir import LOCK_FILE, RunDirInUse, RunLock

    if not (run_dir / LOCK_FILE).exists():
        return False
    try:
        RunLock(run_dir).acquire().release()
    except RunDirInUse:
        return True
    return False


def _metrics_step(run_dir: Path) -> int:
    """The step of metrics.csv's last row (its first column), read from the file's end."""
    path = run_dir / "metrics.csv"
    if not path.is_file():
        return 0
    with path.open("rb") as f:
        f.seek(0, 2)
        f.seek(max(0, f.tell() - 4096))
        lines = f.read().decode("utf-8", "replace").strip().splitlines()
    for line in reversed(lines):
        head = line.split(",", 1)[0]
        if head.isdigit():
            return int(head)
    return 0


def _metrics_rate(run_dir: Path, tail_bytes: int = 16384) -> float | None:
    """Steps per second of wall time over metrics.csv's last rows (about 16 KB of them: the
    last hundred-odd episodes), evaluations included, counting only rows where the agent
    learnt (a ``critic_loss``: not the random steps or a snapshot's refill, several times
    faster); None without two such rows to compare."""
    path = run_dir / "metrics.csv"
    if not path.is_file():
        return None
    with path.open("rb") as f:
        header = f.readline().decode("utf-8", "replace").strip().split(",")
        f.seek(0, 2)
        f.seek(max(0, f.tell() - tail_bytes))
        lines = f.read().decode("utf-8", "replace").splitlines()[1:]  # the first may be cut
    if "step" not in header or "wall_time" not in header:
        return None
    step_at, wall_at = header.index("step"), header.index("wall_time")
    learnt_at = header.index("critic_loss") if "critic_loss" in header else None
    points = []
    for line in lines:
        cells = line.split(",")
        try:
            if learnt_at is not None and not cells[learnt_at].strip():
                continue
            points.append((int(cells[step_at]), float(cells[wall_at])))
        except (IndexError, ValueError):
            continue  # the header, a row being written
    if len(points) < 2 or points[-1][1] <= points[0][1]:
        return None
    return (points[-1][0] - points[0][0]) / (points[-1][1] - points[0][1])


def summary(statuses: Sequence[RunStatus]) -> dict[str, int]:
    """Counts of runs by state, and steps done and in all."""
    counts: dict[str, int] = {state: 0 for state in RUN_STATES}
    for status in statuses:
        counts[status.state] += 1
    counts["steps_done"] = sum(s.steps if s.state == "done" else s.step for s in statuses)
    counts["steps_total"] = sum(s.steps for s in statuses)
    return counts
