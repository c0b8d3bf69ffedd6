"""``ilfo reward`` and ``ilfo demos info | convert | collect``."""

from __future__ import annotations

import argparse
import json
import time
from dataclasses import fields
from pathlib import Path
from typing import Any

import numpy as np

from ilfo import demos
from ilfo.demos.env_check import check_observation_width
from ilfo.envs import CONTACT_FORCE_DIMS, FULL_OBSERVATION_DIMS, match_observation_width
from ilfo.paths import bundled_demos
from ilfo.rewards import OOPS, PWIL, OOPSConfig
from ilfo.training.config import imitation_drops_contact_forces


def _add_reward_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "reward",
        help="Score learner episodes against expert demos with the OOPS (or PWIL) reward.",
        description=(
            "Compute per-step OT rewards of learner episodes against a demonstration and print "
            "one line per episode. By default: the bundled Hopper-v5 scripted rollouts, demo 0 "
            "as the expert, and as learners that demo plus noise and the file's second and last "
            "episodes (in the bundled file: another episode of the same policy and a "
            "random-action one)."
        ),
    )
    p.add_argument("--demos", default=None, help="demo .npz file (default: bundled Hopper-v5)")
    p.add_argument("--expert", type=int, default=0, help="index of the expert episode")
    p.add_argument(
        "--learners", type=int, nargs="*", default=None, help="indices of learner episodes"
    )
    p.add_argument(
        "--rewarder", choices=["oops", "pwil"], default="oops", help="reward (default oops)"
    )
    docs = {f.name: (f.default, f.type) for f in fields(OOPSConfig)}
    p.add_argument(
        "--solver",
        default=None,
        choices=["sinkhorn", "emd", "greedy"],
        help=f"OOPS coupling (default {docs['solver'][0]})",
    )
    p.add_argument(
        "--metric",
        default=None,
        choices=["sqrt_euclidean", "euclidean", "sqeuclidean", "cosine"],
        help=f"OOPS ground cost (default {docs['metric'][0]})",
    )
    p.add_argument(
        "--atoms",
        default=None,
        choices=["transitions", "states"],
        help=f"OOPS atoms: (s, s') or s (default {docs['atoms'][0]})",
    )
    p.add_argument(
        "--reg",
        type=float,
        default=None,
        help=f"Sinkhorn lambda (default {docs['reg'][0]})",
    )
    p.add_argument(
        "--contact-forces",
        action=argparse.BooleanOptionalAction,
        default=None,
        help=(
            "Ant-v5 and Humanoid-v5 demos: score the states with (or without) the contact "
            "forces that end their observations (default: as `ilfo train` imitates, without)"
        ),
    )
    p.add_argument("--json", action="store_true", help="one JSON line per episode")
    p.set_defaults(run=_run_reward)


def _run_reward(args: argparse.Namespace) -> int:
    path = args.demos or bundled_demos("Hopper-v5-scripted")
    data = demos.load(path)
    check_observation_width(data, path)
    episodes = [e.observations for e in data.episodes]
    dropped = imitation_drops_contact_forces(data.env_id, args.contact_forces)
    if dropped:  # a file already without them is left as it is
        width = FULL_OBSERVATION_DIMS[data.env_id] - CONTACT_FORCE_DIMS[data.env_id]
        episodes = [match_observation_width(obs, data.env_id, width) for obs in episodes]
    if not 0 <= args.expert < len(episodes):
        raise ValueError(f"--expert {args.expert} out of range: the file has {len(episodes)}")
    expert = episodes[args.expert]
    learners: list[tuple[str, np.ndarray]] = []
    if args.learners is None:
        noisy = expert + np.random.default_rng(0).normal(0.0, 0.01, expert.shape)
        others = [i for i in range(len(episodes)) if i != args.expert]
        learners.append(("expert + N(0, 0.01^2) noise", noisy))
        for i in dict.fromkeys(others[:1] + others[-1:]):  # the first and last other, once
            learners.append((f"episode {i}", episodes[i]))
    else:
        for i in args.learners:
            if not 0 <= i < len(episodes):
                raise ValueError(f"learner {i} out of range: the file has {len(episodes)}")
            learners.append((f"episode {i}", episodes[i]))
    # None: not given (the OOPS default); PWIL has settings of its own, so these are refused.
    oops_flags = {name: getattr(args, name) for name in ("solver", "metric", "atoms", "reg")}
    given = {name: value for name, value in oops_flags.items() if value is not None}
    rewarder: OOPS | PWIL
    if args.rewarder == "pwil":
        if given:
            flags = ", ".join(f"--{name}" for name in given)
            raise ValueError(f"{flags}: OOPS settings, which --rewarder pwil does not use")
        rewarder = PWIL([expert])
    else:
        rewarder = OOPS([expert], OOPSConfig(**given))
    if not args.json:
        space = " (states without the contact forces)" if dropped else ""
        print(f"{data.env_id} demos from {path}: expert = episode {args.expert}{space}")
        print(
            f"{'learner':30s} {'OT distance':>12s} {'mean reward':>12s} "
            f"{'iters':>6s} {'conv':>5s} {'ms':>8s}"
        )
    for name, obs in learners:
        start = time.perf_counter()
        out = rewarder(obs)
        ms = 1e3 * (time.perf_counter() - start)
        row = {
            "learner": name,
            "ot_distance": out.distance,
            "mean_reward": float(out.rewards.mean()),
            "iterations": out.coupling.iterations,
            "converged": out.coupling.converged,
            "marginal_error": out.coupling.marginal_error,
            "ms": ms,
        }
        if args.json:
            print(json.dumps(row))
        else:
            print(
                f"{name:30s} {out.distance:12.4f} {row['mean_reward']:12.4f} "
                f"{out.coupling.iterations!s:>6s} {out.coupling.converged!s:>5s} {ms:8.1f}"
            )
    return 0


def _add_demos_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "demos",
        help="Inspect and convert demonstration files (ilfo .npz, Minari, D4RL, imitation).",
    )
    dsub = p.add_subparsers(dest="demos_command", required=True)
    i = dsub.add_parser(
        "info",
        help="Episodes, lengths, dims, returns, env id and provenance of a demo file.",
        description="Describe a demonstration file of any format `ilfo demos convert` reads.",
    )
    i.add_argument("file", help="ilfo/imitation .npz, Minari/D4RL .hdf5, or a Minari dataset dir")
    i.add_argument("--json", action="store_true", help="print one JSON object")
    i.set_defaults(run=_run_demos_info)
    c = dsub.add_parser(
        "convert",
        help="Convert a Minari, D4RL or imitation file (or an ilfo one) to ilfo's .npz.",
        description=(
            "Read IN (ilfo or imitation .npz, Minari or D4RL HDF5, Minari dataset directory; the "
            "format is detected from the contents) and write OUT in ilfo's .npz format. D4RL and "
            "imitation files do not record their environment: pass --env-id."
        ),
    )
    c.add_argument("input", metavar="IN", help="demonstration file or Minari dataset directory")
    c.add_argument("output", metavar="OUT", help="ilfo .npz to write")
    c.add_argument("--env-id", default=None, help="environment id to record (overrides IN's)")
    c.add_argument("--force", action="store_true", help="overwrite OUT if it exists")
    c.set_defaults(run=_run_demos_convert)
    k = dsub.add_parser(
        "collect",
        help="Deterministic full-length rollouts of an expert policy, saved as ilfo .npz.",
        description=(
            "Roll out an exported expert (a directory with expert.json and policy.msgpack, or an "
            "env id with a shipped expert) deterministically for the full horizon. Observations "
            "are what a learner sees; actions and rewards are kept for analysis only."
        ),
    )
    k.add_argument("--expert", required=True, help="expert directory or env id")
    k.add_argument("--env", default=None, help="check that the expert is for this env")
    k.add_argument(
        "-n", "--episodes", type=int, default=10, help="episodes to collect (default 10)"
    )
    k.add_argument("--seed", type=int, default=0, help="seed of the first episode (default 0)")
    k.add_argument("--out", required=True, help="ilfo .npz to write (new, or --force)")
    k.add_argument("--force", action="store_true", help="overwrite --out if it exists")
    k.add_argument(
        "--keep-falls",
        action="store_true",
        help="keep episodes in which the expert falls (default: skip them, try the next seed)",
    )
    k.set_defaults(run=_run_demos_collect)


def _check_npz_out(out: Path, force: bool) -> None:
    """An ilfo .npz to write: its name must say so (numpy would add the suffix), and an
    existing file is replaced only with --force."""
    if out.suffix != ".npz":
        raise ValueError(f"the output must be a .npz file, got {out}")
    if out.exists() and not force:
        raise ValueError(f"{out} exists: pass --force to overwrite it")


def _run_demos_collect(args: argparse.Namespace) -> int:
    from ilfo.experts import collect_demos, load_expert

    expert = load_expert(args.expert)
    if args.env and args.env != expert.config.env:
        raise ValueError(f"the expert is for {expert.config.env}, not {args.env}")
    _check_npz_out(Path(args.out), args.force)
    episodes = collect_demos(
        expert, args.episodes, args.out, first_seed=args.seed, skip_falls=not args.keep_falls
    )
    returns = np.array([e.task_score for e in episodes])
    print(
        f"wrote {args.out}: {len(episodes)} episodes of {len(episodes[0].observations) - 1} "
        f"steps, return {returns.mean():.1f} +- {returns.std():.1f} (fixed-horizon score)"
    )
    return 0


def _run_demos_info(args: argparse.Namespace) -> int:
    data = demos.load_any(args.file)
    check_observation_width(data, args.file)
    summary = demos.summarize(data)
    if args.json:
        print(json.dumps(summary))
        return 0
    print(f"{args.file} ({demos.detect_format(args.file)})")
    rows = [
        ("env id", summary["env_id"] or "(not recorded)"),
        ("episodes", summary["episodes"]),
        ("transitions", summary["transitions"]),
        (
            "length (T)",
            f"min {summary['length_min']}  mean {summary['length_mean']:.1f}  "
            f"max {summary['length_max']}",
        ),
        ("obs dim", summary["obs_dim"]),
        ("action dim", "(no actions)" if summary["action_dim"] is None else summary["action_dim"]),
    ]
    if summary["return_mean"] is None:
        rows.append(("return", "(no rewards)"))
    else:
        rows.append(
            (
                "return",
                f"mean {summary['return_mean']:.2f}  std {summary['return_std']:.2f}  "
                f"min {summary['return_min']:.2f}  max {summary['return_max']:.2f}"
                + (
                    "  (without each episode's last row: its next state is not in the file)"
                    if summary["provenance"].get("final_transition_dropped")
                    else ""
                ),
            )
        )
    rows.append(("provenance", json.dumps(summary["provenance"], sort_keys=True)))
    for key, value in rows:
        print(f"{key:>12s}: {value}")
    return 0


def _run_demos_convert(args: argparse.Namespace) -> int:
    out = Path(args.output)
    _check_npz_out(out, args.force)
    data = demos.load_any(args.input)
    env_id = args.env_id or data.env_id
    if not env_id:
        raise ValueError(f"{args.input} does not record its environment: pass --env-id")
    provenance = dict(data.provenance)
    if args.env_id and data.env_id and data.env_id != args.env_id:
        provenance["env_id_overridden_from"] = data.env_id
    demos.save(out, data.episodes, env_id, provenance)
    print(f"wrote {out}: {len(data.episodes)} episodes of {env_id}")
    return 0


def _add_label_parser(sub: argparse._SubParsersAction) -> None:
    from ilfo.config import add_dataclass_arguments
    from ilfo.labelling import LabelConfig

    p = sub.add_parser(
        "label",
        help="Reward every episode of an offline dataset by OT to demos (OTR), same format out.",
        description=(
            "Label an offline dataset (ilfo .npz, Minari HDF5 dataset, D4RL HDF5 file) with "
            "optimal-transport rewards from state-only demos, for offline RL: each episode is "
            "coupled with each demo as OOPS does, each step's transported cost c is squashed "
            "(exponential alpha * exp(-beta c), OTR's; linear -alpha c; or OOPS's own scale) "
            "and the top-k demos' rewards averaged. Writes OUT in the dataset's format; "
            "episodes are labelled in parallel."
        ),
    )
    p.add_argument("dataset", help="the dataset to label")
    p.add_argument("--demos", required=True, help="the expert demos (state-only is enough)")
    p.add_argument("--out", required=True, help="where to write the labelled dataset (new)")
    p.add_argument("--num-demos", type=int, default=None, help="use the first N demos (all)")
    p.add_argument(
        "--env-id",
        default=None,
        help="env id of a dataset that names none (D4RL); checked against the demos'",
    )
    p.add_argument(
        "--contact-forces",
        action=argparse.BooleanOptionalAction,
        default=None,
        help=(
            "Ant-v5 and Humanoid-v5: compare the states with (or without) the contact forces "
            "that end their observations (default: as `ilfo train` imitates, without); the "
            "output keeps every column"
        ),
    )
    p.add_argument(
        "--workers",
        type=int,
        default=None,
        help="processes labelling episodes (default: the CPUs this process may use)",
    )
    add_dataclass_arguments(p, LabelConfig)  # the oops field, a dataclass, gets its group
    group = p.add_argument_group("the OT problem (OOPS's settings)")
    add_dataclass_arguments(
        group,
        OOPSConfig,
        # The labeller's own squashing (--squashing, --alpha, --beta) turns costs into rewards.
        ("demo_selection", "seed", "warm_start", "reward_scale", "kernel", "kernel_rate"),
        prefix="oops",
    )
    p.set_defaults(run=_run_label)


def _run_label(args: argparse.Namespace) -> int:
    import os

    from tqdm import tqdm

    from ilfo.config import overrides_from_args
    from ilfo.labelling import LabelConfig, label_dataset

    if args.workers is not None and args.workers < 1:
        raise ValueError(f"--workers must be >= 1, got {args.workers}")
    oops = OOPSConfig(**overrides_from_args(args, OOPSConfig, prefix="oops"))
    config = LabelConfig(oops=oops, **overrides_from_args(args, LabelConfig))
    cpus = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    workers = args.workers or cpus or 1
    # The bar appears with the first labelled episode, not before the inputs are checked.
    bars: list[Any] = []

    def advance(episodes: int) -> None:
        if not bars:
            bars.append(tqdm(unit="episode", desc="labelling"))
        bars[0].update(episodes)

    try:
        summary = label_dataset(
            args.dataset,
            args.demos,
            args.out,
            config,
            num_demos=args.num_demos,
            env_id=args.env_id,
            contact_forces=args.contact_forces,
            workers=workers,
            on_progress=advance,
        )
    finally:
        for bar in bars:
            bar.close()
    print(
        f"wrote {summary.out} ({summary.format}): {summary.episodes} episodes, "
        f"{summary.transitions} transitions in {summary.seconds:.1f} s with {workers} workers; "
        f"rewards mean {summary.reward_mean:.4g}, std {summary.reward_std:.4g}"
    )
    return 0
