"""Evaluate a finished (or checkpointed) run's policy."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from ilfo.agents import policy_of
from ilfo.envs import make_env
from ilfo.rundir import CONFIG_FILE, latest_checkpoint, load_msgpack, read_run_config
from ilfo.train import BEST_POLICY_FILE, Trainer, config_from_dict, score_policy


def load_run_policy(run_dir: Path, best: bool = False) -> tuple[Trainer, Any, str]:
    """A run's trainer (its config, environments and agent, fresh) and the policy to evaluate:
    ``policy.msgpack`` if the run finished, else its newest checkpoint's; with ``best``,
    ``best_policy.msgpack`` (the best-evaluated policy so far). Returns (trainer, policy,
    which): ``which`` names the policy used."""
    run_dir = Path(run_dir)
    config = config_from_dict(read_run_config(run_dir), run_dir / CONFIG_FILE)
    policy = run_dir / (BEST_POLICY_FILE if best else "policy.msgpack")
    if best and not policy.is_file():
        raise FileNotFoundError(f"{run_dir} has no {BEST_POLICY_FILE} (no evaluation yet)")
    trainer = Trainer(config, run_dir, progress=False)
    if policy.is_file():
        return trainer, load_msgpack(policy_of(trainer.state), policy, "policy"), policy.name
    checkpoint = latest_checkpoint(run_dir)
    if checkpoint is None:
        raise FileNotFoundError(f"{run_dir} has neither policy.msgpack nor a checkpoint")
    state = load_msgpack(trainer.state, checkpoint / "agent.msgpack", "agent checkpoint")
    return trainer, state, "latest checkpoint"


def evaluate_run(
    run_dir: Path, episodes: int = 10, video: str | None = None, best: bool = False
) -> dict[str, Any]:
    """Run deterministic fixed-horizon episodes of a run's policy and summarise them.

    The policy: see ``load_run_policy``.
    """
    if episodes < 1:
        raise ValueError(f"--episodes must be >= 1, got {episodes}")
    trainer, state, which = load_run_policy(run_dir, best)
    config = trainer.config
    env = trainer.eval_env
    if video:
        env = make_env(
            config.env,
            True,
            horizon=trainer.horizon,
            render_mode="rgb_array",
            healthy_angle_range=config.healthy_angle_range,  # as trainer.eval_env
        )
        _check_rendering(env)
    scored = score_policy(
        env,
        trainer.agent,
        state,
        trainer.horizon,
        list(range(episodes)),
        trainer.distance_probe,
        render_first=bool(video),
    )
    result: dict[str, Any] = {
        "env": config.env,
        "algo": config.algo,
        "episodes": episodes,
        "policy": which,
        "score_mean": float(np.mean(scored.scores)),
        "score_std": float(np.std(scored.scores)),
        "return_mean": float(np.mean(scored.returns)),
        "return_std": float(np.std(scored.returns)),
    }
    if not np.isnan(trainer.demo_return):
        result["score_norm"] = result["score_mean"] / trainer.demo_return
        result["return_norm"] = result["return_mean"] / trainer.demo_return
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
        imageio.mimsave(path, frames, fps=fps)
    except Exception as err:  # the ffmpeg plugin raises several kinds
        raise ValueError(f"could not write {path}: {err}") from err
