"""Offline readers for demonstration formats users already have, all returning a ``DemoFile``.

Formats (nothing here imports minari, d4rl or imitation, and nothing is ever unpickled):

``minari``
    A local Minari dataset stored as HDF5: ``<root>/<dataset_id>/data/main_data.hdf5`` with one
    group ``episode_<i>`` per episode holding ``observations`` (T + 1, ...), ``actions`` (T, ...),
    ``rewards`` (T,), ``terminations`` and ``truncations`` (T,). Dict or tuple observations are
    nested groups (tuple members named ``_index_<k>``); they are flattened to (T + 1, d) by
    concatenating the leaves (each reshaped to (T + 1, -1)) in sorted key order (``_index_<k>``
    in numeric order), the order ``gymnasium.spaces.flatten`` uses for a Dict space made from a
    plain dict; the leaf paths and widths go to ``provenance["observation_keys"]`` and
    ``["observation_sizes"]``. Dataset
    metadata (``env_spec`` as a JSON string whose ``id`` is the env id, ``dataset_id``, ...) is
    read from ``metadata.json`` beside the HDF5 file (Minari >= 0.4.2) or, failing that, from the
    attributes of the file's root (older Minari). Arrow/parquet Minari datasets are refused.
``d4rl``
    One HDF5 file of flat arrays: ``observations`` (N, d), ``actions`` (N, a), ``rewards`` (N,),
    ``terminals`` (N,), ``timeouts`` (N,) (at least one of the two), and optionally
    ``next_observations`` (N, d). Episodes end after each row whose terminal or timeout flag is
    set; rows after the last flag form a final (unfinished) episode that is kept, and
    ``provenance["unfinished_last_episode"]`` says so. With ``next_observations`` an episode of
    rows s..e-1 has observations ``observations[s:e]`` plus ``next_observations[e-1]``
    (T = e - s). Without it the state after the last row is unknown, so the last transition of
    every episode is dropped: observations ``observations[s:e]``, actions and rewards of rows
    s..e-2 (T = e - s - 1); one-row episodes then vanish. Both counts go to provenance. D4RL
    files do not name their environment: pass ``env_id``.
``imitation``
    The ``.npz`` written by HumanCompatibleAI/imitation's ``save`` before it moved to HuggingFace
    datasets (imitation <= 0.3): ``obs`` (sum_i (T_i + 1), ...) all trajectories end to end,
    ``acts`` (sum_i T_i, ...), ``rews`` (sum_i T_i,) when the trajectories had rewards,
    ``terminal`` (N,), ``indices`` (N - 1,) = cumsum of T_i without the last, and ``infos``, an
    object array of dicts that needs pickle: it and any other object array are skipped, never
    loaded (their names go to ``provenance["skipped_keys"]``). No env id is stored: pass
    ``env_id``.
``ilfo``
    ilfo's own schema-1 ``.npz`` (``ilfo.demos.npz``).

Every reader checks what it returns: observations (T + 1, d) with T >= 1 and the same d in every
episode, actions (T, a) with the same a, rewards (T,), all finite. A bad file raises ValueError
naming the file and the problem.
"""

from __future__ import annotations

import itertools
import json
import re
import warnings
import zipfile
import zlib
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import Any, Literal

import numpy as np

from ilfo.demos.npz import DemoFile, Episode, checked_episodes, numeric_array
from ilfo.demos.npz import load as _load_ilfo
from ilfo.npz_check import check_npz

Format = Literal["ilfo", "imitation", "minari", "d4rl"]
FORMATS: tuple[str, ...] = ("ilfo", "imitation", "minari", "d4rl")

_HDF5_MAGIC = b"\x89HDF\r\n\x1a\n"
_ZIP_MAGICS = (b"PK\x03\x04", b"PK\x05\x06")
_EPISODE_RE = re.compile(r"episode_(\d+)")
_INDEX_RE = re.compile(r"_index_(\d+)")
_MINARI_FILE = "main_data.hdf5"
_MINARI_METADATA = "metadata.json"
_MINARI_PROVENANCE_KEYS = ("dataset_id", "minari_version", "algorithm_name", "author")
# What h5py raises for unreadable, truncated or corrupt files.
_H5_ERRORS = (OSError, KeyError, RuntimeError, TypeError)
# What np.load / zipfile raise for truncated or corrupt archives.
_NPZ_ERRORS = (zipfile.BadZipFile, zlib.error, OSError, EOFError, KeyError)


# ----------------------------------------------------------------------------------------------
# Top level


def detect_format(path: str | Path) -> Format:
    """Say which reader fits ``path``, from its contents (never its name).

    A directory is a Minari dataset; an HDF5 file is Minari when its root holds ``episode_<i>``
    groups and D4RL when it holds an ``observations`` array; a zip archive (``.npz``) is ilfo's
    when it holds ``schema_version`` and imitation's when it holds ``obs``.

    Raises:
        FileNotFoundError: nothing at ``path``.
        ValueError: unreadable, or none of the formats.
    """
    path = Path(path)
    if path.is_dir():
        return "minari"
    if not path.is_file():
        raise FileNotFoundError(f"no demonstration file at {path}")
    with open(path, "rb") as f:
        head = f.read(8)
    # HDF5's signature sits at byte 0 unless the file has a user block (h5py.is_hdf5 looks on).
    if head == _HDF5_MAGIC or (head[:4] not in _ZIP_MAGICS and _h5py().is_hdf5(path)):
        h5py = _h5py()
        try:
            with h5py.File(path, "r") as f:
                keys = list(f.keys())
        except _H5_ERRORS as err:
            raise ValueError(f"{path} is not a readable HDF5 file ({err})") from None
        if any(_EPISODE_RE.fullmatch(k) for k in keys):
            return "minari"
        if "observations" in keys:
            return "d4rl"
        raise ValueError(
            f"{path}: HDF5 file with neither episode_<i> groups (Minari) nor an 'observations' "
            f"array (D4RL); its top-level keys are {sorted(keys)[:20]}"
        )
    if head[:4] in _ZIP_MAGICS:
        keys = _npz_keys(path)
        if "schema_version" in keys:
            return "ilfo"
        if "obs" in keys:
            return "imitation"
        raise ValueError(
            f"{path}: .npz archive with neither 'schema_version' (ilfo) nor 'obs' (imitation); "
            f"its keys are {sorted(keys)[:20]}"
        )
    raise ValueError(
        f"{path} is in no known demonstration format (neither a .npz archive nor an HDF5 file)"
    )


def load_any(path: str | Path, env_id: str | None = None) -> DemoFile:
    """Read a demonstration file of any supported format (see the module docstring).

    Args:
        path: an ilfo or imitation ``.npz``, a Minari or D4RL HDF5 file, or a Minari dataset
            directory.
        env_id: the environment the demos must come from. Where the file names its environment
            the two must match; where it does not (D4RL, imitation) this becomes the env id.

    Returns:
        A DemoFile whose episodes have observations (T_i + 1, obs_dim), actions (T_i, act_dim)
        or None and rewards (T_i,) or None; ``env_id`` is "" where neither the file nor the
        caller names it. The provenance of a foreign file has ``source_format`` and
        ``source_path``; an ilfo file's is its own.

    Raises:
        FileNotFoundError: nothing at ``path``.
        ValueError: a bad or unknown file, or an env id that does not match the file's.
    """
    fmt = detect_format(path)
    demo = _READERS[fmt](path)
    if env_id and env_id != demo.env_id:
        if demo.env_id:
            raise ValueError(
                f"{path} holds demos of {demo.env_id!r}, not of the requested {env_id!r}"
            )
        demo = replace(demo, env_id=env_id)
    return demo


def summarize(demo: DemoFile) -> dict[str, Any]:
    """Numbers that describe a DemoFile: episode count and lengths (T_i), dims, return stats.

    Returns a JSON-serialisable dict: ``env_id``, ``episodes``, ``transitions`` (sum of T_i),
    ``lengths`` (list of T_i), ``length_min``/``length_mean``/``length_max``, ``obs_dim``,
    ``action_dim`` (None without actions), ``return_mean``/``return_std``/``return_min``/
    ``return_max`` (None unless every episode has rewards; an episode that recorded the steps
    the environment reported as terminated scores them 0, ``Episode.task_score``) and
    ``provenance``.
    """
    if not demo.episodes:
        raise ValueError("no episodes to summarize")
    lengths = [len(e.observations) - 1 for e in demo.episodes]
    first = demo.episodes[0]
    returns = [e.task_score for e in demo.episodes]
    out: dict[str, Any] = {
        "env_id": demo.env_id,
        "episodes": len(lengths),
        "transitions": int(sum(lengths)),
        "lengths": lengths,
        "length_min": min(lengths),
        "length_mean": float(np.mean(lengths)),
        "length_max": max(lengths),
        "obs_dim": int(first.observations.shape[1]),
        "action_dim": None if first.actions is None else int(first.actions.shape[1]),
    }
    stats: dict[str, float | None] = dict.fromkeys(("mean", "std", "min", "max"))
    if all(r is not None for r in returns):
        r = np.asarray(returns, dtype=np.float64)
        stats = {"mean": r.mean(), "std": r.std(), "min": r.min(), "max": r.max()}
    out.update({f"return_{k}": None if v is None else float(v) for k, v in stats.items()})
    out["provenance"] = demo.provenance
    return out


# ----------------------------------------------------------------------------------------------
# Readers


def read_ilfo(path: str | Path) -> DemoFile:
    """Read ilfo's own schema-1 ``.npz``: ``ilfo.demos.load``, which checks everything."""
    return _load_ilfo(path)


def read_imitation(path: str | Path) -> DemoFile:
    """Read an imitation-library trajectory ``.npz`` (keys ``obs``, ``acts``, ``indices``, ...).

    ``obs`` (sum_i (T_i + 1), ...) is split into N = len(indices) + 1 trajectories of T_i + 1
    rows, ``acts`` and ``rews`` (sum_i T_i, ...) at ``indices``. Object arrays (``infos``) are
    skipped without being unpickled. Returns env_id "" (the format does not store one).
    """
    path = Path(path)
    data, skipped = _read_npz(path)
    for key in ("obs", "acts", "rews", "indices", "terminal"):
        if key in skipped:
            raise ValueError(f"{path}: {key!r} is an object array that would need unpickling")
    for key in ("obs", "indices"):
        if key not in data:
            have = sorted([*data, *skipped])
            raise ValueError(f"{path} lacks the key {key!r} of an imitation .npz (keys: {have})")
    indices = data["indices"]
    if indices.ndim != 1 or not np.issubdtype(indices.dtype, np.number):
        raise ValueError(f"{path}: 'indices' must be a 1-D integer array, got {indices.shape}")
    if indices.size and not np.array_equal(indices, np.round(indices)):
        raise ValueError(f"{path}: 'indices' holds non-integers")
    indices = indices.astype(np.int64)
    n = len(indices) + 1
    obs = _rows(data["obs"], "obs", path)
    total_steps = len(obs) - n
    if total_steps < n:
        raise ValueError(
            f"{path}: {len(obs)} obs rows cannot hold {n} trajectories of at least one step"
        )
    bounds = np.concatenate([[0], indices, [total_steps]])
    steps = np.diff(bounds)
    if (steps < 1).any():
        raise ValueError(
            f"{path}: 'indices' {indices.tolist()[:10]} do not split {total_steps} steps into "
            f"{n} trajectories of at least one step each (obs has {len(obs)} rows)"
        )
    extras: dict[str, np.ndarray] = {}
    for key, name in (("acts", "actions"), ("rews", "rewards")):
        if key in data:
            read = _rows if key == "acts" else numeric_array
            value = read(data[key], key, path)
            if value.ndim == 0 or len(value) != total_steps:
                raise ValueError(
                    f"{path}: {key!r} has shape {value.shape}, but obs and indices make "
                    f"{total_steps} steps"
                )
            extras[name] = value
    if "terminal" in data and data["terminal"].shape != (n,):
        raise ValueError(f"{path}: 'terminal' has shape {data['terminal'].shape}, not ({n},)")
    obs_bounds = bounds + np.arange(n + 1)
    episodes = [
        Episode(
            observations=obs[obs_bounds[i] : obs_bounds[i + 1]],
            **{k: v[bounds[i] : bounds[i + 1]] for k, v in extras.items()},
        )
        for i in range(n)
    ]
    provenance: dict[str, Any] = {"source_format": "imitation", "source_path": str(path)}
    if skipped:
        provenance["skipped_keys"] = skipped
    return DemoFile(episodes=checked_episodes(episodes, path), env_id="", provenance=provenance)


def read_minari(path: str | Path) -> DemoFile:
    """Read a local Minari HDF5 dataset: its directory, its ``data/`` or ``main_data.hdf5``.

    Episodes are the root's ``episode_<i>`` groups in order of i; dict/tuple observations are
    flattened to (T + 1, d) (see the module docstring). The env id comes from the dataset's
    ``env_spec`` ("" when it has none).
    """
    path = Path(path)
    h5file = _minari_file(path)
    h5py = _h5py()
    try:
        with h5py.File(h5file, "r") as f:
            meta = _minari_metadata(h5file, f)
            names = minari_episode_names(f)
            if not names:
                raise ValueError(f"{h5file} has no episode_<i> groups: not a Minari dataset")
            episodes = []
            obs_keys: list[tuple[str, int]] | None = None
            for name in names:
                group = f[name]
                if not isinstance(group, h5py.Group):
                    raise ValueError(f"{h5file}: {name} is not a group")
                if "observations" not in group:
                    raise ValueError(f"{h5file}: {name} lacks 'observations'")
                obs, keys = _flatten(group["observations"], f"{name}/observations", h5file)
                if obs_keys is None:
                    obs_keys = keys
                if keys != obs_keys:
                    raise ValueError(
                        f"{h5file}: {name} has observation keys {keys}, episode "
                        f"{names[0]} has {obs_keys}"
                    )
                extras = {}
                for key in ("actions", "rewards"):
                    if key in group:
                        extras[key] = _flatten(group[key], f"{name}/{key}", h5file)[0]
                episodes.append(Episode(observations=obs, **extras))
    except _H5_ERRORS as err:
        raise ValueError(f"{h5file} is not a readable Minari HDF5 file ({err})") from None
    provenance: dict[str, Any] = {"source_format": "minari", "source_path": str(h5file)}
    provenance.update({k: _as_str(meta[k]) for k in _MINARI_PROVENANCE_KEYS if k in meta})
    if obs_keys:
        provenance["observation_keys"] = [k for k, _ in obs_keys]
        provenance["observation_sizes"] = [d for _, d in obs_keys]
    env_id = _env_id_from_spec(meta.get("env_spec"))
    episodes = checked_episodes(episodes, h5file)
    return DemoFile(episodes=episodes, env_id=env_id, provenance=provenance)


def read_d4rl(path: str | Path) -> DemoFile:
    """Read a D4RL-style HDF5 file of flat arrays and split it into episodes.

    See the module docstring for how episodes are cut and how their final state is found.
    Returns env_id "" (D4RL files do not store one).
    """
    path = Path(path)
    h5py = _h5py()
    try:
        with h5py.File(path, "r") as f:
            data = {}
            for key in (
                "observations",
                "next_observations",
                "actions",
                "rewards",
                "terminals",
                "timeouts",
            ):
                if key in f:
                    if not isinstance(f[key], h5py.Dataset):
                        raise ValueError(f"{path}: {key!r} is not an array")
                    data[key] = numeric_array(f[key][()], key, path)
    except _H5_ERRORS as err:
        raise ValueError(f"{path} is not a readable D4RL HDF5 file ({err})") from None
    if "observations" not in data:
        raise ValueError(f"{path} lacks the 'observations' array of a D4RL file")
    if "terminals" not in data and "timeouts" not in data:
        raise ValueError(f"{path} lacks both 'terminals' and 'timeouts': episodes cannot be cut")
    obs = _rows(data["observations"], "observations", path)
    n = len(obs)
    if n == 0:
        raise ValueError(f"{path}: 'observations' is empty")
    for key, value in data.items():
        if value.ndim == 0 or len(value) != n:
            raise ValueError(
                f"{path}: {key!r} has shape {value.shape}, 'observations' has {n} rows"
            )
    next_obs = data.get("next_observations")
    if next_obs is not None:
        next_obs = _rows(next_obs, "next_observations", path)
        if next_obs.shape != obs.shape:
            raise ValueError(
                f"{path}: next_observations {next_obs.shape} do not match observations {obs.shape}"
            )
    done = np.zeros(n, dtype=bool)
    for key in ("terminals", "timeouts"):
        if key in data:
            if data[key].ndim != 1:
                raise ValueError(f"{path}: {key!r} must be 1-D, got shape {data[key].shape}")
            done |= data[key] != 0
    unfinished = not done[-1]
    if "timeouts" not in data:
        _warn_unflagged_time_limits(path, obs, next_obs, done)
    extras = {k: data[k] for k in ("actions", "rewards") if k in data}
    episodes = []
    spans = d4rl_spans(done, next_obs is not None)
    for s, e, stop in spans:
        ep_obs = (
            np.concatenate([obs[s:e], next_obs[e - 1 : e]]) if next_obs is not None else obs[s:e]
        )
        episodes.append(Episode(observations=ep_obs, **{k: v[s:stop] for k, v in extras.items()}))
    dropped = len(np.unique(np.concatenate([[0], np.flatnonzero(done) + 1, [n]]))) - 1 - len(spans)
    if not episodes:
        raise ValueError(f"{path}: no episode has a complete transition")
    provenance: dict[str, Any] = {
        "source_format": "d4rl",
        "source_path": str(path),
        "final_transition_dropped": next_obs is None,
        "unfinished_last_episode": bool(unfinished),
    }
    if dropped:
        provenance["dropped_one_step_episodes"] = dropped
    return DemoFile(episodes=checked_episodes(episodes, path), env_id="", provenance=provenance)


def _warn_unflagged_time_limits(
    path: Path, obs: np.ndarray, next_obs: np.ndarray | None, done: np.ndarray
) -> None:
    """A D4RL file with terminals but no timeouts (older -v0 files) joins an episode that
    ended at the time limit to the next one: say so, counting the joins where the file's next
    observations show them (D4RL's own loader cuts such files by max_episode_steps)."""
    if next_obs is None:
        warnings.warn(
            f"{path} has 'terminals' but no 'timeouts': episodes are cut at terminals only, so "
            "any that ended at the time limit are joined to the next one",
            stacklevel=3,
        )
        return
    continuous = (next_obs[:-1] == obs[1:]).all(axis=1) | done[:-1]
    joins = int((~continuous).sum())
    if joins:
        warnings.warn(
            f"{path} has 'terminals' but no 'timeouts', and at {joins} unflagged rows the next "
            "observation is not the next row's: likely episodes that ended at the time limit, "
            "joined here to the next one",
            stacklevel=3,
        )


def d4rl_spans(done: np.ndarray, has_next_observations: bool) -> list[tuple[int, int, int]]:
    """The episodes of a D4RL file's rows, as (start, end, stop): rows start..end-1 give its
    observations (plus ``next_observations[end - 1]`` where the file has them), rows
    start..stop-1 its transitions (``stop = end`` with next observations, else ``end - 1``: the
    state after the last row is unknown). Episodes end after each row flagged done; one-row
    episodes without next observations have no transition and are left out."""
    n = len(done)
    bounds = np.unique(np.concatenate([[0], np.flatnonzero(done) + 1, [n]]))
    spans = []
    for s, e in itertools.pairwise(bounds.tolist()):
        stop = e if has_next_observations else e - 1
        if stop > s:
            spans.append((s, e, stop))
    return spans


def minari_episode_names(f: Any) -> list[str]:
    """A Minari HDF5 file's ``episode_<i>`` groups in order of i (the episodes' order)."""
    return sorted((k for k in f if _EPISODE_RE.fullmatch(k)), key=lambda k: int(k.split("_")[1]))


_READERS: dict[str, Callable[[str | Path], DemoFile]] = {
    "ilfo": read_ilfo,
    "imitation": read_imitation,
    "minari": read_minari,
    "d4rl": read_d4rl,
}


# ----------------------------------------------------------------------------------------------
# Helpers


def _h5py() -> Any:
    try:
        import h5py
    except ImportError:  # pragma: no cover - h5py is a dependency
        raise ValueError("reading HDF5 demos (Minari, D4RL) needs h5py: pip install h5py") from None
    return h5py


def _npz_keys(path: Path) -> list[str]:
    return [n.removesuffix(".npy") for n in check_npz(path)]


def _read_npz(path: Path) -> tuple[dict[str, np.ndarray], list[str]]:
    """Every array of an .npz, with allow_pickle=False; object arrays are skipped, not loaded."""
    data: dict[str, np.ndarray] = {}
    skipped: list[str] = []
    check_npz(path)
    try:
        with np.load(path, allow_pickle=False) as archive:
            for key in archive.files:
                try:
                    data[key] = archive[key]
                except ValueError as err:
                    if "allow_pickle" not in str(err):
                        raise
                    skipped.append(key)
    except (*_NPZ_ERRORS, ValueError) as err:
        raise ValueError(f"{path} is not a readable .npz archive ({err})") from None
    return data, skipped


def _rows(arr: np.ndarray, name: str, path: Path) -> np.ndarray:
    """(n, ...) numbers as (n, d): trailing axes flattened, a 1-D array taken as (n, 1)."""
    arr = numeric_array(arr, name, path)
    if arr.ndim == 0:
        raise ValueError(f"{path}: {name!r} is a scalar, not an array of rows")
    return arr.reshape(arr.shape[0], int(np.prod(arr.shape[1:], dtype=np.int64)))


def _flatten(node: Any, name: str, path: Path) -> tuple[np.ndarray, list[tuple[str, int]]]:
    """An HDF5 dataset, or a nested group of them, as one (n, d) array.

    Group members are taken in sorted key order (``_index_<k>`` members of a tuple in numeric
    order) and each reshaped to (n, -1). Also returns (leaf path below ``node``, width) for every
    leaf of a group, [] for a plain dataset.
    """
    h5py = _h5py()
    leaves: list[tuple[str, Any]] = []

    def walk(item: Any, rel: str) -> None:
        if isinstance(item, h5py.Dataset):
            leaves.append((rel, item))
            return
        if not isinstance(item, h5py.Group):
            raise ValueError(f"{path}: {name}/{rel} is neither an array nor a group")
        keys = list(item.keys())
        if not keys:
            raise ValueError(f"{path}: {'/'.join(filter(None, (name, rel)))} is an empty group")
        if all(_INDEX_RE.fullmatch(k) for k in keys):
            keys.sort(key=lambda k: int(k.rsplit("_", 1)[1]))
        else:
            keys.sort()
        for key in keys:
            walk(item[key], f"{rel}/{key}" if rel else key)

    walk(node, "")
    parts = [_rows(ds[()], "/".join(filter(None, (name, rel))), path) for rel, ds in leaves]
    lengths = {len(p) for p in parts}
    if len(lengths) != 1:
        raise ValueError(f"{path}: the members of {name} have different lengths {sorted(lengths)}")
    keys = [(rel, p.shape[1]) for (rel, _), p in zip(leaves, parts, strict=True) if rel]
    return np.concatenate(parts, axis=1), keys


def _minari_file(path: Path) -> Path:
    if path.is_file():
        return path
    if not path.is_dir():
        raise FileNotFoundError(f"no Minari dataset at {path}")
    for data_dir in (path / "data", path):
        if (data_dir / _MINARI_FILE).is_file():
            return data_dir / _MINARI_FILE
        meta = data_dir / _MINARI_METADATA
        if meta.is_file():
            fmt = _read_json(meta).get("data_format", "hdf5")
            if fmt != "hdf5":
                raise ValueError(
                    f"{path} is a Minari dataset stored as {fmt!r}; only HDF5 datasets can be "
                    f"read (re-save it with data_format='hdf5')"
                )
    raise ValueError(f"{path} holds no Minari {_MINARI_FILE} (looked in {path}/data and {path})")


def _read_json(path: Path) -> dict[str, Any]:
    try:
        out = json.loads(path.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as err:
        raise ValueError(f"{path} is not readable JSON ({err})") from None
    except RecursionError:
        raise ValueError(f"{path} is not readable JSON: nested too deeply") from None
    if not isinstance(out, dict):
        raise ValueError(f"{path} does not hold a JSON object")
    return out


def _minari_metadata(h5file: Path, f: Any) -> dict[str, Any]:
    meta_path = h5file.parent / _MINARI_METADATA
    if meta_path.is_file():
        return _read_json(meta_path)
    return dict(f.attrs)


def _as_str(value: Any) -> str:
    if isinstance(value, bytes):
        return value.decode("utf-8", "replace")
    if isinstance(value, np.ndarray) and value.size == 1:
        return _as_str(value.item())
    return str(value)


def _env_id_from_spec(spec: Any) -> str:
    """The ``id`` of a Gymnasium EnvSpec serialised as JSON ("" where absent or unreadable)."""
    if spec is None:
        return ""
    if not isinstance(spec, dict):
        try:
            spec = json.loads(_as_str(spec))
        except json.JSONDecodeError:
            return ""
    env_id = spec.get("id") if isinstance(spec, dict) else None
    return env_id if isinstance(env_id, str) else ""
