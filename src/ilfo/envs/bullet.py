"""PyBullet's Minitaur and MinitaurDuck (the paper's two PyBullet tasks) as gymnasium environments.

``pybullet_envs`` (inside the ``pybullet`` wheel: ``pip install -e ".[bullet]"``) is written for the
old ``gym`` and imports ``pkg_resources``; neither is installed here. This module loads only the six
files that Minitaur needs (``pybullet_envs/bullet/{minitaur_gym_env, minitaur_duck_gym_env,
minitaur, motor, minitaur_env_randomizer, env_randomizer_base}.py``) as a private package, with
stand-ins for ``gym`` and ``pkg_resources`` placed in ``sys.modules`` only while they import:
``pybullet_envs/__init__.py`` (which registers every env with the old gym) never runs, and
``sys.modules`` and ``sys.path`` are left as they were.

The adapted environments are the original classes with their default arguments (the paper's
``gym.make("MinitaurBulletEnv-v0")``), with three changes:

- the reset-time randomisation of the robot (masses, battery voltage, motor damping, foot
  friction: same ranges and distributions as ``MinitaurEnvRandomizer``) draws from the
  environment's own generator, seeded by ``reset(seed=...)``, instead of the global ``random``
  and ``np.random``; the simulation itself is deterministic, so a seed fixes the episode;
- the physics always runs headless in its own ``pybullet.DIRECT`` client (the original first tries
  to attach to a shared-memory server) and prints nothing;
- the gymnasium API: ``reset(seed) -> (obs, info)``, ``step -> (obs, reward, terminated,
  truncated, info)``; observations are float32 (28: 8 motor angles, 8 motor velocities, 8 motor
  torques, the base orientation quaternion), actions float32 in [-1, 1]^8 (leg swing and
  extension of the four legs; the original raises ``ValueError`` beyond 1.01).

``terminated`` is the original ``done`` (the robot fell, or for the duck task the duck touched
the ground); the 1,000-step limit is gymnasium's ``TimeLimit``, as in ``pybullet_envs``' registry.
The ids are registered with gymnasium when ``ilfo.envs`` is imported; pybullet itself is only
imported when an environment is made.
"""

from __future__ import annotations

import importlib
import importlib.util
import os
import sys
import types
from functools import cache
from typing import Any, ClassVar

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from gymnasium.utils import seeding

MINITAUR_ENV_ID = "MinitaurBulletEnv-v0"
MINITAUR_DUCK_ENV_ID = "MinitaurBulletDuckEnv-v0"
BULLET_ENVS: tuple[str, ...] = (MINITAUR_ENV_ID, MINITAUR_DUCK_ENV_ID)
MAX_EPISODE_STEPS = 1000

INSTALL_HINT = 'PyBullet is not installed: pip install -e ".[bullet]" (pybullet==3.2.7)'
_PACKAGE = "ilfo._pybullet_minitaur"  # the private package the Minitaur files are loaded into

# MinitaurEnvRandomizer's ranges (pybullet_envs/bullet/minitaur_env_randomizer.py).
_BASE_MASS_ERROR_RANGE = (-0.2, 0.2)  # relative
_LEG_MASS_ERROR_RANGE = (-0.2, 0.2)  # relative
_BATTERY_VOLTAGE_RANGE = (14.8, 16.8)  # volt
_MOTOR_VISCOUS_DAMPING_RANGE = (0.0, 0.01)  # N m s / rad
_FOOT_FRICTION_RANGE = (0.8, 1.5)


def _stand_ins() -> dict[str, types.ModuleType]:
    """Just enough of old ``gym`` and of ``pkg_resources`` for the Minitaur files to import."""
    # Any: modules built here, whose attributes the type checker cannot know.
    gym_mod: Any = types.ModuleType("gym")
    gym_mod.__version__ = "0.26.2"  # only compared with 0.9.6, to skip pre-0.9.6 aliases

    class Env:  # the original classes' base; the adapter below supplies gymnasium's API
        pass

    def box(low: Any, high: Any, dtype: Any = np.float32) -> types.SimpleNamespace:
        return types.SimpleNamespace(low=np.asarray(low), high=np.asarray(high), dtype=dtype)

    gym_mod.Env = Env
    spaces_mod: Any = types.ModuleType("gym.spaces")
    spaces_mod.Box = box
    utils_mod: Any = types.ModuleType("gym.utils")
    seeding_mod: Any = types.ModuleType("gym.utils.seeding")
    seeding_mod.np_random = seeding.np_random
    utils_mod.seeding = seeding_mod
    gym_mod.spaces, gym_mod.utils = spaces_mod, utils_mod
    pkg_resources: Any = types.ModuleType("pkg_resources")
    pkg_resources.parse_version = lambda v: tuple(int(p) for p in v.split(".")[:3])
    return {
        "gym": gym_mod,
        "gym.spaces": spaces_mod,
        "gym.utils": utils_mod,
        "gym.utils.seeding": seeding_mod,
        "pkg_resources": pkg_resources,
    }


@cache
def _minitaur_modules() -> tuple[types.ModuleType, types.ModuleType]:
    """Load ``minitaur_gym_env`` and ``minitaur_duck_gym_env`` without ``pybullet_envs``' init."""
    try:
        importlib.import_module("pybullet")
        spec = importlib.util.find_spec("pybullet_envs")  # finds it without running its __init__
    except ImportError as err:
        raise ImportError(INSTALL_HINT) from err
    if spec is None or not spec.submodule_search_locations:
        raise ImportError(f"pybullet_envs not found. {INSTALL_HINT}")
    bullet_dir = [os.path.join(p, "bullet") for p in spec.submodule_search_locations]
    package = types.ModuleType(_PACKAGE)
    package.__path__ = bullet_dir
    package.__package__ = _PACKAGE
    # The private package stays in sys.modules: its modules' relative imports need it.

    stand_ins = _stand_ins()
    saved_modules = {name: sys.modules.get(name) for name in stand_ins}
    saved_path = list(sys.path)  # minitaur_gym_env.py puts site-packages first in sys.path
    sys.modules.update(stand_ins)
    sys.modules[_PACKAGE] = package
    try:
        # Any: modules loaded by name, whose attributes the type checker cannot know.
        plain: Any = importlib.import_module(f"{_PACKAGE}.minitaur_gym_env")
        duck: Any = importlib.import_module(f"{_PACKAGE}.minitaur_duck_gym_env")
    except ImportError as err:
        raise ImportError(f"cannot load PyBullet's Minitaur ({err}). {INSTALL_HINT}") from err
    finally:
        sys.path[:] = saved_path
        for name, module in saved_modules.items():
            if module is None:
                sys.modules.pop(name, None)
            else:
                sys.modules[name] = module
    pybullet = importlib.import_module("pybullet")
    bullet_client: Any = importlib.import_module("pybullet_utils.bullet_client")

    class DirectClient(bullet_client.BulletClient):  # pybullet_utils' client, always headless
        def __init__(self, *args: Any, **kwargs: Any) -> None:
            # BulletClient() would try a shared-memory server first, and connecting with its
            # options="" prints "argv[0]=" from C.
            self._shapes: dict[Any, Any] = {}
            self._pid = os.getpid()
            self._client = pybullet.connect(pybullet.DIRECT)
            if self._client < 0:
                raise RuntimeError("pybullet could not start a DIRECT physics client")

    for minitaur_module in (plain, duck):
        # Only these private copies are patched: headless, and no "urdf_root=..." print.
        minitaur_module.bc = types.SimpleNamespace(BulletClient=DirectClient)
        minitaur_module.print = lambda *args, **kwargs: None
    return plain, duck


class _SeededRandomizer:
    """``MinitaurEnvRandomizer`` drawing from the adapter's generator, not global randomness."""

    def __init__(self, owner: _MinitaurAdapter) -> None:
        self._owner = owner

    def randomize_env(self, env: Any) -> None:
        rng = self._owner.np_random
        minitaur = env.minitaur
        base_mass = minitaur.GetBaseMassFromURDF()
        minitaur.SetBaseMass(rng.uniform(*(base_mass * (1.0 + e) for e in _BASE_MASS_ERROR_RANGE)))
        leg_masses = np.asarray(minitaur.GetLegMassesFromURDF(), dtype=np.float64)
        low, high = (leg_masses * (1.0 + e) for e in _LEG_MASS_ERROR_RANGE)
        minitaur.SetLegMasses([float(x) for x in rng.uniform(low, high)])
        minitaur.SetBatteryVoltage(float(rng.uniform(*_BATTERY_VOLTAGE_RANGE)))
        minitaur.SetMotorViscousDamping(float(rng.uniform(*_MOTOR_VISCOUS_DAMPING_RANGE)))
        minitaur.SetFootFriction(float(rng.uniform(*_FOOT_FRICTION_RANGE)))


class _MinitaurAdapter(gym.Env):
    """A gymnasium environment around one of ``pybullet_envs``' Minitaur environments."""

    # A step is 0.01 s of physics (5 substeps of 2 ms): 100 frames a second in real time.
    # gymnasium annotates Env.metadata as an instance attribute, though it is class data.
    metadata: ClassVar[dict[str, Any]] = {  # type: ignore[misc]
        "render_modes": ["rgb_array"],
        "render_fps": 100,
    }
    _duck: ClassVar[bool] = False

    def __init__(self, render_mode: str | None = None) -> None:
        if render_mode not in (None, "rgb_array"):
            raise ValueError(f"render_mode must be None or 'rgb_array', got {render_mode!r}")
        plain, duck = _minitaur_modules()
        cls = duck.MinitaurBulletDuckEnv if self._duck else plain.MinitaurBulletEnv
        self.render_mode = render_mode
        # The original resets once while it is built; that draw is discarded by the first reset.
        self._env = cls(render=False, env_randomizer=_SeededRandomizer(self))
        act, obs = self._env.action_space, self._env.observation_space
        self.action_space = spaces.Box(
            act.low.astype(np.float32), act.high.astype(np.float32), dtype=np.float32
        )
        self.observation_space = spaces.Box(
            obs.low.astype(np.float32), obs.high.astype(np.float32), dtype=np.float32
        )

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        super().reset(seed=seed)
        return np.asarray(self._env.reset(), dtype=np.float32), {}

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        obs, reward, done, info = self._env.step(np.asarray(action, dtype=np.float64).ravel())
        return np.asarray(obs, dtype=np.float32), float(reward), bool(done), False, dict(info)

    def render(self) -> np.ndarray | None:
        if self.render_mode != "rgb_array":
            return None
        frame = np.asarray(self._env.render(mode="rgb_array"), dtype=np.uint8)
        return np.ascontiguousarray(frame)

    def close(self) -> None:
        client = getattr(getattr(self, "_env", None), "_pybullet_client", None)
        if client is not None and client._client >= 0:
            client.disconnect()
        super().close()


class MinitaurBulletEnv(_MinitaurAdapter):
    """``pybullet_envs.bullet.MinitaurBulletEnv``: walk forward, penalised for energy."""


class MinitaurBulletDuckEnv(_MinitaurAdapter):
    """``pybullet_envs.bullet.MinitaurBulletDuckEnv``: the same with a duck on the robot's back;
    the episode also terminates when the duck falls off."""

    _duck = True


def register_bullet_envs() -> None:
    """Register the two ids with gymnasium (1,000-step limit); idempotent, imports no pybullet."""
    for env_id, cls, threshold in (
        (MINITAUR_ENV_ID, "MinitaurBulletEnv", 15.0),
        (MINITAUR_DUCK_ENV_ID, "MinitaurBulletDuckEnv", 5.0),
    ):
        if env_id not in gym.registry:
            gym.register(
                env_id,
                entry_point=f"{__name__}:{cls}",
                max_episode_steps=MAX_EPISODE_STEPS,
                reward_threshold=threshold,
            )
