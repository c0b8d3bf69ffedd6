"""Evaluate a finished (or checkpointed) run's policy."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from ilfo.training import load_demo_set, load_run_policy, score_policy
from ilfo.training.config import check_eval_episodes
from ilfo.training.rollout import evaluation_seeds


def evaluate_run(
    run_dir: Path, episodes: int = 10, video: str | None = None, best: bool = False
) -> dict[str, Any]:
    """Run deterministic fixed-horizon episodes of a run's policy and summarise them, on the
    run's evaluation seeds (``rollout.evaluation_seeds``: not the demos'); ``episodes`` from 1
    to ``config.MAX_EVAL_EPISODES``.

    The policy: ``policy.msgpack`` if the run finished, else its newest checkpoint's; with
    ``best``, ``best_policy.msgpack`` (``training.load_run_policy``).
    """
    check_eval_episodes(episodes, "--episodes")
    run = load_run_policy(run_dir, "best" if best else "final")
    config, horizon = run.config, run.env.horizon
    demos = load_demo_set(config, run.env.obs_dim)
    env = run.eval_env(render_mode="rgb_array" if video else None)
    if video:
        _check_rendering(env)
    scored = score_policy(
        env,
        run.agent,
        run.policy,
        horizon,
        evaluation_seeds(config.seed, episodes),
        demos.distance_probe,
        render_first=bool(video),
    )
    result: dict[str, Any] = {
        "env": config.env,
        "algo": config.algo,
        "episodes": episodes,
        "policy": run.source,
        "score_mean": float(np.mean(scored.scores)),
        "score_std": float(np.std(scored.scores)),
        "return_mean": float(np.mean(scored.returns)),
        "return_std": float(np.std(scored.returns)),
    }
    if not np.isnan(demos.mean_return):
        result["score_norm"] = result["score_mean"] / demos.mean_return
        result["return_norm"] = result["return_mean"] / demos.mean_return
    if len(scored.distances):
        result["ot_distance"] = float(np.mean(scored.distances))
    if video:
        _write_video(video, scored.frames, fps=int(env.metadata.get("render_fps", 50)))
        result["video"] = video
    return result


def _check_rendering(env: Any) -> None:
    """Fail early, and say why, where this machine cannot render offscreen."""
    try:
        env.reset(seed=0)
        env.render()
    except Exception as err:  # MuJoCo raises FatalError and others without OpenGL
        raise ValueError(
            f"--video: offscreen rendering is unavailable here ({type(err).__name__}: {err}). "
            "MuJoCo needs OpenGL: set MUJOCO_GL=egl (with a GPU driver) or MUJOCO_GL=osmesa "
            "(with Debian's libosmesa6), or evaluate without --video."
        ) from None


def _write_video(path: str, frames: list[np.ndarray], fps: int) -> None:
    try:
        import imageio.v2 as imageio
    except ImportError as err:
        raise ValueError(
            "--video needs imageio and imageio-ffmpeg: pip install imageio-ffmpeg"
        ) from err
    try:
        # imageio's stubs ask for list[ArrayLike], and list is invariant: list[np.ndarray] fails.
        imageio.mimsave(path, frames, fps=fps)  # type: ignore[arg-type]
    except Exception as err:  # the ffmpeg plugin raises several kinds
        raise ValueError(f"could not write {path}: {err}") from err
