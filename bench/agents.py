"""Benchmark agent updates per second: ilfo's TD3 and TD7 (JAX, jitted lax.scan), TD3 also
against a minimal eager PyTorch TD3 with the same networks, and all against the machine's
matmul FLOP rate.

Cases: TD3 presets ``paper`` (actor 256-256, twin critics 1024-1024, batch 100) and ``fast``
(critics 256-256), both with the PAL loss, critic gradient-norm clipping at 25, time
augmentation, target policy smoothing, policy delay 2 and Polyak tau 0.003; TD7 ``td7`` (the
authors' sizes: widths 256, batch 256) and ``td7-fast`` (widths 128, batch 100), both with time
augmentation; dims ``hopper`` (obs 11 + 1 time feature, act 3), ``ant`` (obs 27 + 1, act 8: Ant
without its contact forces, as imitation observes it) and ``humanoid`` (obs 376 + 1, act 17).
Batches are drawn uniformly from a replay buffer of random transitions (100k by default).

- ilfo: ``make_td3(...).update(state, data, size, num_updates=N)`` (one jitted scan of N
  updates), timed after a warm-up call so that compilation is excluded; best of ``--repeat``.
- torch: the update written out in eager PyTorch (``TorchTD3`` below): two critic
  ``nn.Sequential``, Adam 3e-4, the same PAL loss and clipping, batches drawn with
  ``torch.randint`` from tensors, ``torch.set_num_threads`` = usable cores; best of
  ``--repeat`` blocks of ``--torch-updates`` updates after a warm-up.
- FLOPs per update: matmul FLOPs that one update needs, averaged over the policy delay (see
  ``flops_per_update``); the machine rate is the best of a 2048x2048 float32 matmul in numpy and
  in JAX. ``fraction_of_matmul`` = achieved / machine rate. ``layer_matmul_gflops`` is the JAX
  rate of the critic's hidden-layer matmul alone, (batch, width) x (width, width): a ceiling
  closer to what an update's small matmuls can reach than the 2048x2048 rate.

    python bench/agents.py                      # table
    python bench/agents.py --json               # one JSON line per case and implementation
    python bench/agents.py --quick              # smoke run: few updates, one repeat
    python bench/agents.py --presets paper --dims humanoid --no-torch
    python bench/agents.py --presets fast paper td7 td7-fast --dims ant --no-torch

Without PyTorch installed the ilfo rows are still measured (torch is reported as skipped).
"""

from __future__ import annotations

import argparse
import itertools
import json
import os
import statistics
import sys
import time
from collections.abc import Callable
from datetime import date
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

# Keep this folder off the path: bench/ot.py would shadow POT's `ot` for anything importing it.
sys.path = [p for p in sys.path if Path(p or ".").resolve() != Path(__file__).resolve().parent]
from ilfo.agents.td3 import TD3Config, make_td3
from ilfo.agents.td7 import TD7Config, make_td7
from ilfo.benchmarking import machine
from ilfo.replay import ReplayData

DIMS = {"hopper": (11 + 1, 3), "ant": (27 + 1, 8), "humanoid": (376 + 1, 17)}
PRESETS: dict[str, Callable[[], TD3Config | TD7Config]] = {
    "paper": TD3Config.paper,
    "fast": TD3Config.fast,
    "td7": TD7Config,
    "td7-fast": TD7Config.fast,
}
DEFAULT_DIMS = ("hopper", "humanoid")


def _torch_version() -> str:
    try:
        import torch
    except ImportError:
        return "not installed"
    return torch.__version__


# ------------------------------------------------------------------------------ FLOP count
def _layers(in_dim: int, hidden: tuple[int, ...], out_dim: int) -> list[tuple[int, int]]:
    dims = [in_dim, *hidden, out_dim]
    return list(itertools.pairwise(dims))


def _mm(layers: list[tuple[int, int]]) -> int:
    """FLOPs of one sample through the layers' matmuls: 2 * in * out each."""
    return sum(2 * i * o for i, o in layers)


def flops_per_update(cfg: TD3Config, obs_dim: int, action_dim: int) -> float:
    """Matmul FLOPs one TD3 update needs, averaged over the policy delay.

    Per sample, with F(net) the forward matmul FLOPs (2 * in * out per layer):
    - TD target: target actor forward + num_critics target critics forward;
    - critic loss: num_critics critics forward, backward = weight gradients (F) + input
      gradients of every layer but the first (the input is data);
    - every ``policy_delay`` updates, the actor loss: actor forward, critic 1 forward, critic 1
      backward for the input gradient only (all layers: d/d action; its weights are constants),
      actor backward = weight gradients (F) + input gradients of all but the first layer.
    Times the batch size. Biases, activations, Adam, Polyak and sampling are not counted.
    """
    actor = _layers(obs_dim, cfg.actor_hidden, action_dim)
    critic = _layers(obs_dim + action_dim, cfg.critic_hidden, 1)
    k = cfg.num_critics
    target = _mm(actor) + k * _mm(critic)
    critic_step = k * (_mm(critic) + _mm(critic) + _mm(critic[1:]))
    actor_step = _mm(actor) + 2 * _mm(critic) + _mm(actor) + _mm(actor[1:])
    return float(cfg.batch_size * (target + critic_step + actor_step / cfg.policy_delay))


def flops_per_update_td7(cfg: TD7Config, obs_dim: int, action_dim: int) -> float:
    """Matmul FLOPs one TD7 update needs, averaged over the policy delay, counted as
    ``flops_per_update`` counts TD3's (backward = weight gradients + input gradients of every
    layer whose input is not data):
    - encoder step: zs(s') forward, zs(s) and zsa forward and backward;
    - critic step: the targets' zs(s'), actor, zsa and critics forward; the fixed encoder's
      zs(s) and zsa forward; the critics forward and backward;
    - every ``policy_delay`` updates, the actor step: the fixed zs(s), the actor, zsa and the
      critics forward; the critics' and zsa's input gradients, the actor's backward.
    Times the batch size."""
    h_e, h_a, h_c, z, k = (
        cfg.encoder_hidden,
        cfg.actor_hidden,
        cfg.critic_hidden,
        cfg.zs_dim,
        cfg.num_critics,
    )
    zs = [(obs_dim, h_e), (h_e, h_e), (h_e, z)]
    zsa = [(z + action_dim, h_e), (h_e, h_e), (h_e, z)]
    actor = [(obs_dim, h_a), (h_a + z, h_a), (h_a, h_a), (h_a, action_dim)]
    critic = [(obs_dim + action_dim, h_c), (h_c + 2 * z, h_c), (h_c, h_c), (h_c, 1)]
    encoder_step = 2 * _mm(zs) + _mm(zsa) + (_mm(zs) + _mm(zs[1:])) + 2 * _mm(zsa)
    critic_step = (
        _mm(zs)
        + _mm(actor)
        + _mm(zsa)
        + k * _mm(critic)
        + _mm(zs)
        + _mm(zsa)
        + k * (2 * _mm(critic) + _mm(critic[1:]))
    )
    actor_step = (
        _mm(zs)
        + _mm(actor)
        + _mm(zsa)
        + k * _mm(critic)
        + k * _mm(critic)
        + _mm(zsa)
        + _mm(actor)
        + _mm(actor[1:])
    )
    return float(cfg.batch_size * (encoder_step + critic_step + actor_step / cfg.policy_delay))


def matmul_gflops(n: int = 2048, repeat: int = 5) -> dict[str, float]:
    """Best float32 n x n matmul rate (GFLOP/s) of numpy and of JAX (jitted, on CPU)."""
    rng = np.random.default_rng(0)
    a = rng.standard_normal((n, n), dtype=np.float32)
    b = rng.standard_normal((n, n), dtype=np.float32)
    flops = 2.0 * n**3
    out = {}
    a @ b
    out["numpy"] = flops / best_time(lambda: a @ b, repeat) / 1e9
    ja, jb = jnp.asarray(a), jnp.asarray(b)
    dot = jax.jit(jnp.dot)
    dot(ja, jb).block_until_ready()
    out["jax"] = flops / best_time(lambda: dot(ja, jb).block_until_ready(), repeat) / 1e9
    return out


def best_time(fn: Callable[[], object], repeat: int) -> float:
    return min(timings(fn, repeat))


def timings(fn: Callable[[], object], repeat: int) -> list[float]:
    out = []
    for _ in range(repeat):
        start = time.perf_counter()
        fn()
        out.append(time.perf_counter() - start)
    return out


# ---------------------------------------------------------------------------------- data
def random_replay(size: int, obs_dim: int, action_dim: int, seed: int = 0) -> dict[str, np.ndarray]:
    """Random transitions; the last observation feature is a time feature in (0, 1]."""
    rng = np.random.default_rng(seed)
    obs = rng.standard_normal((size, obs_dim), dtype=np.float32)
    next_obs = rng.standard_normal((size, obs_dim), dtype=np.float32)
    obs[:, -1] = rng.integers(1, 1001, size) / 1000
    next_obs[:, -1] = np.maximum(obs[:, -1] - 1e-3, 0.0)
    return {
        "obs": obs,
        "action": rng.uniform(-1, 1, (size, action_dim)).astype(np.float32),
        "reward": rng.standard_normal(size, dtype=np.float32),
        "next_obs": next_obs,
        "not_done": (rng.random(size) > 0.001).astype(np.float32),
    }


# ---------------------------------------------------------------------------------- ilfo
def bench_ilfo(
    cfg: TD3Config | TD7Config,
    obs_dim: int,
    action_dim: int,
    data: dict,
    num_updates: int,
    repeat: int,
) -> list[float]:
    """Seconds per update of each timed call of the compiled ``update`` (compiled ahead of time,
    so compilation is excluded; the best of several calls drops first-call effects)."""
    make = make_td7 if isinstance(cfg, TD7Config) else make_td3
    agent = make(cfg, obs_dim, action_dim, max_action=1.0)
    replay = ReplayData(**{k: jnp.asarray(v) for k, v in data.items()})
    size = len(data["reward"])
    state = agent.init(0)
    update = agent.update.lower(state, replay, size, num_updates=num_updates).compile()
    out = []
    for _ in range(repeat):
        start = time.perf_counter()
        state, metrics = update(state, replay, size)
        jax.block_until_ready((state, metrics))
        out.append((time.perf_counter() - start) / num_updates)
    if not np.isfinite(float(metrics["critic_loss"])):
        raise RuntimeError(f"ilfo's {type(cfg).__name__} diverged on the benchmark data")
    return out


def layer_matmul_gflops(batch: int, width: int, repeat: int, chain: int = 200) -> float:
    """JAX rate (GFLOP/s) of the (batch, width) x (width, width) float32 matmul that dominates
    an update: ``chain`` of them in one jitted loop, so dispatch is amortised."""
    w = jax.random.normal(jax.random.PRNGKey(0), (width, width)) / np.sqrt(width)
    x = jax.random.normal(jax.random.PRNGKey(1), (batch, width))
    run = jax.jit(lambda x, w: jax.lax.fori_loop(0, chain, lambda _, y: y @ w, x))
    run(x, w).block_until_ready()
    seconds = best_time(lambda: run(x, w).block_until_ready(), repeat)
    return 2.0 * batch * width * width * chain / seconds / 1e9


# --------------------------------------------------------------------------------- torch
def make_torch_td3(
    cfg: TD3Config, obs_dim: int, action_dim: int, max_action: float = 1.0, adam: str = "default"
):
    """A minimal eager PyTorch TD3 (Fujimoto's reference structure) with ilfo's options.

    ``adam``: ``default`` (torch's choice: the per-tensor loop on CPU), ``foreach`` or ``fused``.
    Returns ``update(data, size)``: one update from a batch drawn with ``torch.randint``.
    """
    import copy

    import torch
    from torch import nn

    def mlp(in_dim: int, hidden: tuple[int, ...], out_dim: int) -> nn.Sequential:
        layers: list[nn.Module] = []
        for width in hidden:
            layers += [nn.Linear(in_dim, width), nn.ReLU()]
            in_dim = width
        layers.append(nn.Linear(in_dim, out_dim))
        return nn.Sequential(*layers)

    actor = mlp(obs_dim, cfg.actor_hidden, action_dim)
    critics = nn.ModuleList(
        [mlp(obs_dim + action_dim, cfg.critic_hidden, 1) for _ in range(cfg.num_critics)]
    )
    actor_target, critics_target = copy.deepcopy(actor), copy.deepcopy(critics)
    for p in [*actor_target.parameters(), *critics_target.parameters()]:
        p.requires_grad_(False)
    adam_kw = {} if adam == "default" else {adam: True}
    actor_opt = torch.optim.Adam(actor.parameters(), lr=cfg.lr_actor, **adam_kw)
    critic_opt = torch.optim.Adam(critics.parameters(), lr=cfg.lr_critic, **adam_kw)
    obs_mean = torch.zeros(obs_dim)
    obs_std = torch.ones(obs_dim)
    noise_scale = cfg.target_noise * max_action
    noise_clip = cfg.noise_clip * max_action
    alpha, m = cfg.pal_alpha, cfg.pal_min_priority
    pairs = list(
        zip(
            [*actor.parameters(), *critics.parameters()],
            [*actor_target.parameters(), *critics_target.parameters()],
            strict=True,
        )
    )
    step = 0

    def pi(net: nn.Module, obs: torch.Tensor) -> torch.Tensor:
        return max_action * torch.tanh(net(obs))

    def q_all(nets: nn.ModuleList, obs: torch.Tensor, action: torch.Tensor) -> torch.Tensor:
        x = torch.cat([obs, action], dim=-1)
        return torch.stack([net(x)[:, 0] for net in nets])  # (num_critics, B)

    def pal(td: torch.Tensor) -> torch.Tensor:
        abs_td = td.abs()
        per_sample = torch.where(
            abs_td < m, m**alpha * 0.5 * td**2, m * abs_td ** (1 + alpha) / (1 + alpha)
        )
        norm = abs_td.max(dim=0).values.clamp(min=m).pow(alpha).mean().detach()
        return per_sample.mean(dim=-1).sum() / norm

    def update(data: dict[str, torch.Tensor], size: int) -> None:
        nonlocal step
        idx = torch.randint(0, size, (cfg.batch_size,))
        obs, action, reward = data["obs"][idx], data["action"][idx], data["reward"][idx]
        next_obs, not_done = data["next_obs"][idx], data["not_done"][idx]
        critic_obs = obs
        if cfg.time_augmentation:  # as ilfo's augment_time: time-to-go k now, k - 1 next
            k = torch.randint(1, cfg.max_time + 1, (cfg.batch_size,)).float()
            critic_obs, next_obs = obs.clone(), next_obs.clone()
            critic_obs[:, -1] = k / cfg.max_time
            next_obs[:, -1] = (k - 1.0) / cfg.max_time
            not_done = (k > 1.0).float()
        obs_n = (obs - obs_mean) / obs_std
        critic_obs_n = (critic_obs - obs_mean) / obs_std
        next_obs_n = (next_obs - obs_mean) / obs_std
        with torch.no_grad():
            next_action = pi(actor_target, next_obs_n)
            if cfg.target_noise > 0:
                noise = (torch.randn_like(next_action) * noise_scale).clamp(-noise_clip, noise_clip)
                next_action = (next_action + noise).clamp(-max_action, max_action)
            next_q = q_all(critics_target, next_obs_n, next_action).min(dim=0).values
            target = reward + cfg.gamma * not_done * next_q
        td = q_all(critics, critic_obs_n, action) - target
        loss = pal(td) if cfg.loss == "pal" else (td**2).mean(dim=-1).sum()
        critic_opt.zero_grad()
        loss.backward()
        if cfg.critic_grad_clip is not None:
            nn.utils.clip_grad_norm_(critics.parameters(), cfg.critic_grad_clip)
        critic_opt.step()
        step += 1
        if step % cfg.policy_delay == 0:
            x = torch.cat([obs_n, pi(actor, obs_n)], dim=-1)
            actor_loss = -critics[0](x).mean()
            actor_opt.zero_grad()
            actor_loss.backward()
            actor_opt.step()
            with torch.no_grad():
                for p, p_target in pairs:
                    p_target.lerp_(p, cfg.tau)

    return update


def bench_torch(
    cfg: TD3Config,
    obs_dim: int,
    action_dim: int,
    data: dict,
    num_updates: int,
    repeat: int,
    threads: int | None = None,
    adam: str = "default",
) -> list[float]:
    """Seconds per update of each timed block of ``num_updates`` eager updates."""
    import torch

    torch.set_num_threads(threads or len(os.sched_getaffinity(0)))
    torch.manual_seed(0)
    tensors = {k: torch.from_numpy(v) for k, v in data.items()}
    size = len(data["reward"])
    update = make_torch_td3(cfg, obs_dim, action_dim, adam=adam)
    for _ in range(max(10, num_updates // 10)):
        update(tensors, size)
    out = []
    for _ in range(repeat):
        start = time.perf_counter()
        for _ in range(num_updates):
            update(tensors, size)
        out.append((time.perf_counter() - start) / num_updates)
    return out


# ---------------------------------------------------------------------------------- main
def torch_available() -> bool:
    try:
        import torch  # noqa: F401
    except ImportError:
        return False
    return True


def run(args: argparse.Namespace) -> tuple[list[dict], dict[str, float], list[str]]:
    rates = matmul_gflops(repeat=2 if args.quick else 5)
    peak = max(rates.values())
    notes = []
    use_torch = not args.no_torch and torch_available()
    if not args.no_torch and not use_torch:
        notes.append("torch skipped: PyTorch is not importable (pip install torch==2.13.0)")
    rows: list[dict] = []
    for preset in args.presets:
        for dims in args.dims:
            obs_dim, action_dim = DIMS[dims]
            cfg = PRESETS[preset]()
            td7 = isinstance(cfg, TD7Config)
            flops = (flops_per_update_td7 if td7 else flops_per_update)(cfg, obs_dim, action_dim)
            critic_width = cfg.critic_hidden if td7 else cfg.critic_hidden[-1]
            data = random_replay(args.buffer, obs_dim, action_dim)
            base = {
                "bench": "agent_update",
                "preset": preset,
                "dims": dims,
                "obs_dim": obs_dim,
                "action_dim": action_dim,
                "batch_size": cfg.batch_size,
                "critic_hidden": [critic_width] if td7 else list(cfg.critic_hidden),
                "flops_per_update": flops,
                "machine_matmul_gflops": round(peak, 2),
                "layer_matmul_gflops": round(
                    layer_matmul_gflops(cfg.batch_size, critic_width, args.repeat + 2), 2
                ),
            }
            impls: list[tuple[str, Callable[..., list[float]], int, dict]] = [
                ("ilfo", bench_ilfo, args.updates, {})
            ]
            if use_torch and not td7:  # the eager twin is TD3's
                torch_kw = {"threads": args.torch_threads, "adam": args.torch_adam}
                impls.append(("torch", bench_torch, args.torch_updates, torch_kw))
            for impl, fn, n, kw in impls:
                per_update = fn(cfg, obs_dim, action_dim, data, n, args.repeat, **kw)
                ups = 1.0 / min(per_update)
                achieved = flops * ups / 1e9
                rows.append(
                    {
                        **base,
                        "impl": impl,
                        "updates_per_s": round(ups, 2),
                        "updates_per_s_median": round(1.0 / statistics.median(per_update), 2),
                        "timed_updates": n * args.repeat,
                        "achieved_gflops": round(achieved, 3),
                        "fraction_of_matmul": round(achieved / peak, 4),
                        **(
                            {"torch_threads": args.torch_threads, "torch_adam": args.torch_adam}
                            if impl == "torch"
                            else {}
                        ),
                    }
                )
    for r in rows:
        if r["impl"] != "ilfo":
            continue
        twin = [t for t in rows if t["impl"] == "torch" and t["preset"] == r["preset"]]
        twin = [t for t in twin if t["dims"] == r["dims"]]
        if twin:
            r["speedup_vs_torch"] = round(r["updates_per_s"] / twin[0]["updates_per_s"], 2)
    return rows, rates, notes


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--json", action="store_true", help="one JSON line per case and impl")
    parser.add_argument("--quick", action="store_true", help="smoke run: few updates, 1 repeat")
    parser.add_argument("--presets", nargs="+", choices=list(PRESETS), default=list(PRESETS))
    parser.add_argument("--dims", nargs="+", choices=list(DIMS), default=list(DEFAULT_DIMS))
    parser.add_argument("--updates", type=int, default=1000, help="ilfo updates per timed call")
    parser.add_argument(
        "--torch-updates", type=int, default=300, help="torch updates per timed block"
    )
    parser.add_argument("--repeat", type=int, default=3, help="timed calls/blocks; best is kept")
    parser.add_argument("--buffer", type=int, default=100_000, help="replay transitions")
    parser.add_argument("--no-torch", action="store_true", help="measure ilfo only")
    parser.add_argument(
        "--torch-threads",
        type=int,
        default=len(os.sched_getaffinity(0)),
        help="torch.set_num_threads (default: all cores; on a loaded machine OpenMP's spinning "
        "makes more threads than free cores catastrophically slow, use 1 there)",
    )
    parser.add_argument(
        "--torch-adam",
        choices=("default", "foreach", "fused"),
        default="default",
        help="torch Adam implementation (default: torch's own choice, as a plain script gets)",
    )
    args = parser.parse_args()
    if args.quick:
        args.updates, args.torch_updates, args.repeat = 50, 20, 1
        args.buffer = min(args.buffer, 10_000)
    rows, rates, notes = run(args)
    meta = {
        "date": date.today().isoformat(),
        "machine": machine(jax=jax.__version__, torch=_torch_version()),
    }
    if args.json:
        for r in rows:
            print(json.dumps({**r, **meta}))
        for note in notes:
            print(json.dumps({"bench": "agent_update", "note": note, **meta}))
        return
    print(f"# {meta['date']}, {meta['machine']}")
    print(
        f"# 2048x2048 float32 matmul: numpy {rates['numpy']:.1f} GFLOP/s, "
        f"jax {rates['jax']:.1f} GFLOP/s (machine rate = the larger)"
    )
    for note in notes:
        print(f"# {note}")
    if any(r["impl"] == "torch" for r in rows):
        print(f"# torch threads: {args.torch_threads}, Adam: {args.torch_adam}")
    print(
        "| preset | dims | impl | updates/s (best) | updates/s (median) | MFLOP/update "
        "| GFLOP/s | % of matmul rate | layer matmul GFLOP/s |"
    )
    print("|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        print(
            f"| {r['preset']} | {r['dims']} | {r['impl']} | {r['updates_per_s']:.1f} "
            f"| {r['updates_per_s_median']:.1f} | {r['flops_per_update'] / 1e6:.1f} "
            f"| {r['achieved_gflops']:.1f} | {100 * r['fraction_of_matmul']:.1f}% "
            f"| {r['layer_matmul_gflops']:.1f} |"
        )
    for r in rows:
        if r["impl"] == "ilfo":
            vs = f"{r['speedup_vs_torch']:.2f}x torch, " if "speedup_vs_torch" in r else ""
            print(
                f"{r['preset']}/{r['dims']}: ilfo {r['updates_per_s']:.0f} updates/s, {vs}"
                f"{100 * r['fraction_of_matmul']:.0f}% of the matmul rate"
            )


if __name__ == "__main__":
    main()
