"""What a run's settings ask of the machine's memory, checked before the run allocates it.

The declared ranges (``ilfo.ranges``) bound each setting alone; a run's memory is their product
with its environment's sizes (replay capacity x observation width, network widths squared,
batch x widths), known once the environment is made, and with its demos' lengths (an optimal
transport reward's matrices, horizon x demo atoms in float64). ``check_memory`` refuses a run whose
estimate exceeds the machine's memory, naming the settings that need it, rather than letting
the run fail (or the kernel kill it, without a message) at its first allocation or update.
"""

from __future__ import annotations

import dataclasses
import itertools
import os
from collections.abc import Sequence
from typing import Any, NamedTuple

from ilfo.algos import AGENT_PARTS
from ilfo.config import flag_name
from ilfo.ranges import declaration

FLOAT_BYTES = 4
"""Replay buffers, networks and batches are float32."""
COPIES = 4
"""Floats per network parameter: the parameter, its target's and Adam's two moments."""
ACTIVATION_PASSES = 4
"""Floats per unit and sample in an update: the forward passes (online and target) and their
gradients, roughly."""
OT_BYTES = 8
"""The OT solvers' matrices are float64."""
OT_MATRICES = {
    "sinkhorn": (4, "the cost, the kernel, Newton's plan and its scaled copy"),
    "emd": (2, "the cost and the plan"),
    "greedy": (2, "the cost and the plan"),
}
"""Episode atoms x demo atoms matrices a solver holds at once (at least: POT's network simplex
holds more); Sinkhorn's Newton steps add a square system on the side with fewer atoms."""
OT_REWARD_SOLVERS = {"oops_adv": "sinkhorn", "sil": "sinkhorn", "pwil": "greedy"}
"""The solver of each OT reward but OOPS (whose config names its own)."""


class MemoryNeed(NamedTuple):
    """One part of a run's memory estimate."""

    what: str
    """The settings behind it, as a message names them."""
    bytes: int


def machine_memory() -> int | None:
    """This machine's physical memory in bytes; None where the system does not say."""
    try:
        pages, page_size = os.sysconf("SC_PHYS_PAGES"), os.sysconf("SC_PAGE_SIZE")
    except (AttributeError, OSError, ValueError):
        return None
    return pages * page_size if pages > 0 and page_size > 0 else None


def memory_needs(
    config: Any, obs_dim: int, action_dim: int, horizon: int, demo_lengths: Sequence[int] = ()
) -> list[MemoryNeed]:
    """The estimate of a ``TrainConfig``'s run on an env of those sizes, by what needs it: the
    replay buffer (an on-policy agent's: its batch and an episode), then per part its
    networks and its batches, then with the demos' ``demo_lengths`` (their steps) its
    optimal transport (``ot_need``)."""
    width = obs_dim + int(config.uses_fixed_horizon)  # the time feature
    row = 2 * width + action_dim + 2  # obs, next_obs, action, reward, not_done
    agent = config.agent_config(horizon)
    if AGENT_PARTS[config.recipe.agent].on_policy:
        capacity = agent.batch_steps + horizon
        setting = f"batch_steps {agent.batch_steps:,} + the horizon {horizon:,}"
        flag = flag_name("batch_steps", config.recipe.agent)
    else:
        capacity = config.replay_capacity
        setting, flag = f"replay_capacity {capacity:,}", "--replay-capacity"
    sizes = f"(2 x {width} + {action_dim} + 2)"
    needs = [MemoryNeed(f"{setting} x {sizes} floats ({flag})", capacity * row * FLOAT_BYTES)]
    parts = [(config.recipe.agent, agent)]
    if config.recipe.reward is not None:
        parts.append((config.recipe.reward, config.part_config(config.recipe.reward)))
    for name, part in parts:
        needs += _part_needs(name, part, width + action_dim, row)
    if demo_lengths:
        needs.append(ot_need(config, horizon, demo_lengths))
    return needs


def ot_need(config: Any, horizon: int, demo_lengths: Sequence[int]) -> MemoryNeed:
    """The largest optimal transport solve of a run imitating demos of ``demo_lengths`` steps:
    its reward's, an episode of ``horizon`` atoms against a demo (OOPS: the longest, or all
    of them pooled; PWIL: all of them, subsampled), or the OT distance that evaluations log
    (Sinkhorn against the first demo), whichever is larger; they are not solved at once."""
    solves = []
    reward = config.recipe.reward
    if reward == "oops":
        oops = config.part_config("oops")
        pooled = oops.demo_selection == "pooled"
        demo = sum(demo_lengths) if pooled else max(demo_lengths)
        # ``nearest`` keeps each demo's plan until it has chosen one.
        kept = len(demo_lengths) - 1 if oops.demo_selection == "nearest" else 0
        solves.append((f"OOPS's {oops.solver}", oops.solver, demo, kept))
    elif reward in OT_REWARD_SOLVERS:
        solver = OT_REWARD_SOLVERS[reward]
        demo = max(demo_lengths)
        if reward == "pwil":
            pwil = config.part_config("pwil")
            demo = -(-sum(demo_lengths) // pwil.subsample)
        solves.append((f"{reward.upper()}'s {solver}", solver, demo, 0))
    solves.append(("the evaluations' OT distance (Sinkhorn)", "sinkhorn", demo_lengths[0], 0))
    needs = []
    for what, solver, demo, kept in solves:
        count, held = OT_MATRICES[solver]
        floats = (count + kept) * horizon * demo
        shown = f"{what}: horizon {horizon:,} x {demo:,} demo atoms x {count + kept} matrices"
        shown += f" ({held}{f', {kept} more plans' if kept else ''})"
        if solver == "sinkhorn":
            floats += min(horizon, demo) ** 2
            shown += f" + {min(horizon, demo):,}^2 (Newton's system)"
        needs.append(MemoryNeed(f"{shown}, float64 (--horizon)", floats * OT_BYTES))
    return max(needs, key=lambda need: need.bytes)


def _part_needs(name: str, part: Any, inputs: int, row: int) -> list[MemoryNeed]:
    """A part's networks (every field declared as widths, each a network from and to
    ``inputs`` units, its critics ``num_critics`` times; a single width, three layers of it)
    and its batches (of transitions of ``row`` floats, and the networks' activations)."""
    params, units, sized = 0, 0, []
    for field in dataclasses.fields(part):
        declared = declaration(type(part), field.name)
        kind = declared.kind if declared is not None else ""
        if kind not in ("widths", "width"):
            continue
        value = getattr(part, field.name)
        layers = list(value) if kind == "widths" else [value] * 3
        copies = getattr(part, "num_critics", 1) if "critic" in field.name else 1
        params += copies * sum(a * b for a, b in itertools.pairwise([inputs, *layers, inputs]))
        units += copies * sum(layers)
        shown = " ".join(map(str, value)) if kind == "widths" else str(value)
        sized.append(f"{field.name} {shown}" + f" x {copies}" * (copies > 1))
    needs = []
    if sized:
        what = f"{name} networks ({', '.join(sized)}: parameters, targets, Adam's moments)"
        needs.append(MemoryNeed(what, params * COPIES * FLOAT_BYTES))
    for field in dataclasses.fields(part):
        declared = declaration(type(part), field.name)
        if declared is not None and declared.kind == "batch":
            batch = getattr(part, field.name)
            floats = batch * (row + units * ACTIVATION_PASSES)
            what = f"{name}.{field.name} {batch:,} x ({row} floats + {units:,} units' activations)"
            flag = flag_name(field.name, name)
            needs.append(MemoryNeed(f"{what} ({flag})", floats * FLOAT_BYTES))
    return needs


def check_memory(
    config: Any, obs_dim: int, action_dim: int, horizon: int, demo_lengths: Sequence[int] = ()
) -> None:
    """A ValueError where the run's estimate (``memory_needs``) exceeds this machine's memory,
    naming the largest needs; nothing where the system does not say how much it has."""
    available = machine_memory()
    if available is None:
        return
    needs = memory_needs(config, obs_dim, action_dim, horizon, demo_lengths)
    needs.sort(key=lambda n: -n.bytes)
    total = sum(n.bytes for n in needs)
    if total <= available:
        return
    largest = "; ".join(f"{n.what} ~{size_text(n.bytes)}" for n in needs[:2])
    raise ValueError(
        f"this run needs ~{size_text(total)} of memory and this machine has "
        f"{size_text(available)}: {largest}"
    )


def size_text(count: int) -> str:
    """A number of bytes as "12.3 GiB"."""
    if count < 1024:
        return f"{count} bytes"
    size, unit = count / 1024, "KiB"
    for larger in ("MiB", "GiB", "TiB"):
        if size < 1024:
            break
        size, unit = size / 1024, larger
    return f"{size:.1f} {unit}"
