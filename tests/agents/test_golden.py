"""Golden digests: a fixed, short sequence of updates of every agent (and of Sinkhorn's solver)
from a fixed seed on fixed synthetic data gives the parameters recorded in ``tests/golden/``.

A refactor must leave them bit-identical; a change that means to change the numbers
regenerates them, and says so in its commit:

    PYTHONPATH=src python -m pytest tests/agents/test_golden.py --update-golden

Each file holds, per leaf of the final state, its float64 sum and sum of absolute values, and a
sha256 of every leaf's bytes (float leaves as float32). The sums are compared on every machine,
to a tolerance far below what a changed update moves them by; the sha256 only where the
platform (CPU, jax, numpy, scipy) is the one that wrote the file, since XLA's and BLAS's
rounding may differ elsewhere in the last bits.
"""

from __future__ import annotations

import hashlib
import json
import platform
from collections.abc import Callable
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import jaxlib
import numpy as np
import pytest
import scipy

from ilfo.agents import SACConfig, TD3Config, ddpg_config, make_sac, make_td3
from ilfo.agents.base import OnPolicyBatch
from ilfo.agents.td7 import TD7Config, make_td7
from ilfo.agents.trpo import TRPOConfig, make_trpo
from ilfo.composition.learned import (
    LearnedRewardSetup,
    RewardSchedule,
    RolloutPlan,
    with_learned_reward,
)
from ilfo.composition.opolo import OPOLOConfig, make_opolo
from ilfo.ot import sinkhorn
from ilfo.replay import ReplayData
from ilfo.rewards import (
    FIRL,
    Discriminator,
    DiscriminatorConfig,
    FIRLConfig,
    expert_transitions,
)

GOLDEN = Path(__file__).resolve().parents[1] / "golden"
OBS, ACT, MAX_ACTION, HORIZON, N = 4, 2, 2.0, 50, 120
# Update counts per call: 2 (whole policy-delay groups), 1, then 2 again (one by one, the count
# no longer aligned with the delay): both paths of the delayed agents run, two compilations.
CHUNKS = (2, 1, 2)
# Large rates, so that a changed update moves the parameters well beyond the tolerance.
LR = 1e-2
TD3_SMALL = {"actor_hidden": (16, 16), "critic_hidden": (16, 16), "batch_size": 8}
TD3_RATES = {"lr_actor": LR, "lr_critic": LR, "max_time": HORIZON}


def _replay(time_feature: bool) -> ReplayData:
    """Fixed synthetic transitions; the last column counts down, a time feature, if asked."""
    rng = np.random.default_rng(0)
    obs = rng.normal(size=(N, OBS)).astype(np.float32)
    next_obs = (obs + 0.1 * rng.normal(size=(N, OBS))).astype(np.float32)
    action = rng.uniform(-MAX_ACTION, MAX_ACTION, (N, ACT)).astype(np.float32)
    reward = (np.sin(obs[:, 0]) + 0.5 * action[:, 0]).astype(np.float32)
    not_done = (rng.uniform(size=N) > 0.05).astype(np.float32)
    if time_feature:
        t = rng.integers(1, HORIZON + 1, N)
        obs = np.column_stack([obs, t / HORIZON]).astype(np.float32)
        next_obs = np.column_stack([next_obs, (t - 1) / HORIZON]).astype(np.float32)
    return ReplayData(*map(jnp.asarray, (obs, action, reward, next_obs, not_done)))


def _demos() -> list[np.ndarray]:
    rng = np.random.default_rng(1)
    return [np.cumsum(rng.normal(0, 0.3, (HORIZON + 1, OBS)), 0).astype(np.float32)] * 2


def _normalised(agent: Any, time_feature: bool) -> Any:
    dim = OBS + int(time_feature)
    mean = np.linspace(-0.2, 0.3, dim).astype(np.float32)
    std = np.linspace(0.8, 1.5, dim).astype(np.float32)
    return agent.set_normalizer(agent.init(0), mean, std)


def _off_policy(agent: Any, time_feature: bool, after: Callable | None = None) -> Any:
    state = _normalised(agent, time_feature)
    data = _replay(time_feature)
    for chunk in CHUNKS:
        state, _ = agent.update(state, data, N, num_updates=chunk)
        if after is not None:
            state = after(state)
    return state


def _td3(config: TD3Config) -> Any:
    time = config.time_augmentation
    return _off_policy(make_td3(config, OBS + int(time), ACT, MAX_ACTION), time)


def _setup(reward: Any, schedule: RewardSchedule | None, **extra: Any) -> LearnedRewardSetup:
    expert = expert_transitions(_demos(), min_count=8)
    return LearnedRewardSetup(reward, schedule, expert, expert.obs, False, **extra)


def _discriminator() -> Discriminator:
    return Discriminator(DiscriminatorConfig(hidden=(16,), batch_size=8, lr=LR))


def _gaifo_td3() -> Any:
    agent = make_td3(TD3Config(**TD3_SMALL, **TD3_RATES), OBS, ACT, MAX_ACTION)
    return _off_policy(
        with_learned_reward(agent, _setup(_discriminator(), RewardSchedule(3, 2))), False
    )


def _firl_sac() -> Any:
    firl = FIRL(FIRLConfig(reward_hidden=(16,), disc_hidden=16, disc_blocks=1, disc_batch_size=16,
                           disc_steps=3, expert_resample=1, reward_lr=LR))  # fmt: skip
    trajs = jnp.asarray(np.stack([demo[1:] for demo in _demos()]))  # states s_1..s_T
    setup = _setup(firl, None, rollouts=RolloutPlan(10, 2), expert_trajectories=trajs)
    agent = with_learned_reward(make_sac(SAC_SMALL, OBS, ACT), setup)
    rollouts = np.random.default_rng(2).normal(size=(2, HORIZON, OBS)).astype(np.float32)
    return _off_policy(agent, False, after=lambda s: agent.learn_from_rollouts(s, rollouts)[0])


def _opolo() -> Any:
    config = OPOLOConfig(
        actor_hidden=(16,), critic_hidden=(16,), idm_hidden=(16,), batch_size=8, lr=LR,
        idm_pretrain_steps=3, idm_every=4, idm_steps=2,
    )  # fmt: skip
    setup = _setup(_discriminator(), RewardSchedule(3, 2))
    return _off_policy(make_opolo(config, OBS, ACT, MAX_ACTION, setup), False)


def _trpo(config: TRPOConfig) -> Any:
    agent = make_trpo(config, OBS, ACT, MAX_ACTION)
    state = _normalised(agent, False)
    data = _replay(False)
    end = np.zeros(N, bool)
    end[[29, 59, 99, N - 1]] = True
    for _ in range(3):
        action = agent.act(state, data.obs, jax.random.PRNGKey(int(state.iterations)))
        reward = np.asarray(data.reward) - 0.1 * np.sum(np.asarray(action) ** 2, -1)
        state, _ = agent.learn(state, OnPolicyBatch(data.obs, action, reward, end))
    return state


def _sinkhorn() -> dict[str, Any]:
    """Plans and potentials of the three accelerations, on an easy and an ill-conditioned
    problem (where Newton takes over), and on weights with a zero."""
    rng = np.random.default_rng(3)
    x, y = rng.normal(size=(40, 3)), rng.normal(size=(30, 3))
    cost = np.sqrt(((x[:, None] - y[None]) ** 2).sum(-1))
    a = rng.uniform(0.5, 1.5, 40)
    a[[3, 17]] = 0.0
    out = {}
    for acceleration in ("none", "overrelax", "newton"):
        for name, kwargs in (
            ("easy", {"reg": 0.5}),
            ("hard", {"reg": 0.01}),
            ("zeros", {"a": a / a.sum(), "reg": 0.05}),
        ):
            result = sinkhorn(cost, acceleration=acceleration, tol=1e-9, **kwargs)
            out[f"{acceleration}_{name}"] = {
                "plan": result.plan,
                "f": np.where(np.isfinite(result.f), result.f, 0.0),
                "g": result.g,
                "iterations": np.asarray(result.iterations),
                "converged": np.asarray(result.converged),
            }
    return out


TD3_FAST = TD3Config.fast(**TD3_SMALL, **TD3_RATES)
# The paper's preset with wider critics than the actor, and the other time augmentation.
TD3_PAPER_NEXT_ONLY = TD3Config.paper(
    **{**TD3_SMALL, **TD3_RATES, "critic_hidden": (32, 32)}, time_augmentation_scheme="next_only"
)
TD3_REFERENCE = TD3Config(
    **TD3_SMALL,
    **TD3_RATES,
    critic_layer_norm=True,
    init_scheme="glorot",
    loss="huber",
    critic_grad_clip=1.0,
)
TD7_SMALL = TD7Config.fast(
    zs_dim=8,
    encoder_hidden=16,
    actor_hidden=16,
    critic_hidden=16,
    batch_size=8,
    target_update_every=3,
    max_time=HORIZON,
    lr_actor=LR,
)
TRPO_SMALL = TRPOConfig(hidden=(16,), value_iters=5, batch_steps=N)
TRPO_EXACT = TRPOConfig(
    hidden=(16, 8), value_iters=5, batch_steps=N, code_fisher=False, kl_check=False, max_kl=0.5
)
SAC_SMALL = SACConfig(**TD3_SMALL, lr_actor=LR)
SAC_FIXED = SACConfig(**TD3_SMALL, autotune=False, critic_grad_clip=1.0)

CASES: dict[str, Callable[[], Any]] = {
    "td3_fast": lambda: _td3(TD3_FAST),
    "td3_paper_next_only": lambda: _td3(TD3_PAPER_NEXT_ONLY),
    "td3_reference_layer_norm": lambda: _td3(TD3_REFERENCE),
    "ddpg": lambda: _td3(ddpg_config(TD3_FAST)),
    "sac": lambda: _off_policy(make_sac(SAC_SMALL, OBS, ACT, MAX_ACTION), False),
    "sac_fixed_temperature": lambda: _off_policy(make_sac(SAC_FIXED, OBS, ACT), False),
    "td7": lambda: _off_policy(make_td7(TD7_SMALL, OBS + 1, ACT, MAX_ACTION), True),
    "trpo": lambda: _trpo(TRPO_SMALL),
    "trpo_exact_fisher": lambda: _trpo(TRPO_EXACT),
    "gaifo_td3": _gaifo_td3,
    "firl_sac": _firl_sac,
    "opolo": _opolo,
    "sinkhorn": _sinkhorn,
}


def _platform() -> str:
    cpu = platform.processor()
    cpuinfo = Path("/proc/cpuinfo")
    if cpuinfo.is_file():
        names = [ln for ln in cpuinfo.read_text().splitlines() if ln.startswith("model name")]
        cpu = names[0].split(":", 1)[1].strip() if names else cpu
    return (
        f"{platform.machine()} {cpu}; jax {jax.__version__} jaxlib {jaxlib.__version__} "
        f"numpy {np.__version__} scipy {scipy.__version__}"
    )


def digest(tree: Any) -> dict[str, Any]:
    """Per leaf (by its path): float64 sum and sum of |x|; a sha256 of all leaves' bytes."""
    sha = hashlib.sha256()
    sums, abs_sums = {}, {}
    for path, leaf in jax.tree_util.tree_flatten_with_path(tree)[0]:
        name = jax.tree_util.keystr(path)
        x = np.asarray(leaf)
        if np.issubdtype(x.dtype, np.floating):
            x = x.astype(np.float32)
        sha.update(f"{name} {x.dtype} {x.shape}".encode())
        sha.update(np.ascontiguousarray(x).tobytes())
        sums[name] = float(np.sum(x, dtype=np.float64))
        abs_sums[name] = float(np.sum(np.abs(x), dtype=np.float64))
    return {"sha256": sha.hexdigest(), "sums": sums, "abs_sums": abs_sums}


@pytest.mark.parametrize("case", sorted(CASES))
def test_updates_give_the_golden_parameters(case, request):
    got = digest(CASES[case]())
    path = GOLDEN / f"{case}.json"
    if request.config.getoption("--update-golden"):
        GOLDEN.mkdir(exist_ok=True)
        path.write_text(json.dumps({"platform": _platform(), **got}, indent=1) + "\n")
        return
    golden = json.loads(path.read_text())
    assert got["sums"].keys() == golden["sums"].keys(), "the state's leaves changed"
    off = {
        name: (got["sums"][name], total)
        for name, total in golden["sums"].items()
        if abs(got["sums"][name] - total) > 1e-5 * golden["abs_sums"][name] + 1e-9
    }
    assert not off, f"leaf sums (now, golden) differ: {off}"
    if golden["platform"] == _platform():
        assert got["sha256"] == golden["sha256"], "same platform, not bit-identical"
