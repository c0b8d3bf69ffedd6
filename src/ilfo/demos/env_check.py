"""Demos checked against the environment they name: observations as wide as it observes.

A file whose ``env_id`` says Hopper-v5 and whose observations are 5 wide cannot come from
Hopper-v5 (11); scoring or describing it as Hopper's would mislead. The width an env observes
is read off one instance of it, made once per process (``observation_widths``).
"""

from __future__ import annotations

import functools
import warnings
from pathlib import Path

from ilfo.demos.npz import DemoFile


@functools.cache
def observation_widths(env_id: str) -> tuple[int, ...] | None:
    """The observation widths a demo of ``env_id`` may have: its observation space's, and for
    Ant-v5 and Humanoid-v5 also that without the contact forces (what ``ilfo train``
    imitates); None where gymnasium does not know the id or cannot make the env here (an
    optional dependency missing): nothing to check against."""
    import gymnasium as gym
    import numpy as np

    from ilfo.envs import CONTACT_FORCE_DIMS  # registers the Minitaur ids too

    try:
        gym.spec(env_id)
    except gym.error.Error:
        return None
    try:
        with warnings.catch_warnings():  # an old version's notice: not this check's business
            warnings.simplefilter("ignore")
            env = gym.make(env_id)
    except Exception:  # made only to learn its width: no env, no check
        return None
    try:
        shape = env.observation_space.shape
    finally:
        env.close()
    if not shape:  # a Dict or Tuple space: demos hold it flattened, by rules of their own
        return None
    width = int(np.prod(shape))
    forces = CONTACT_FORCE_DIMS.get(env_id)
    return (width,) if forces is None else (width, width - forces)


def check_observation_width(demo: DemoFile, path: str | Path) -> None:
    """Raise a ValueError naming ``path`` where ``demo``'s observations are not as wide as the
    env it names observes (no check for a file that names none, or an env unknown here)."""
    if not demo.env_id or not demo.episodes:
        return
    widths = observation_widths(demo.env_id)
    width = demo.episodes[0].observations.shape[1]
    if widths is None or width in widths:
        return
    expected = " or ".join(map(str, widths))
    raise ValueError(
        f"{path} holds observations {width} wide, but {demo.env_id} observes {expected}: "
        "not demos of that env (a wrong env_id, or another version of it?)"
    )
