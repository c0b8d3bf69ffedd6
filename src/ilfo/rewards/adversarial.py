"""SIL's adversarial critic: a learned embedding whose cosine distance is the OT ground cost.

As in the Sinkhorn Imitation Learning authors' code (docs/notes/sil-spec.md, sections 3 and 4):
the critic f_theta is an MLP on atoms ((s, s') here), hidden (128, 128) ReLU, a linear output of
30 features, PyTorch's default initialisation (weights and biases uniform in +-1/sqrt(fan_in)),
trained by Adam with no regularisation. The cost between a learner episode's atoms X and an
expert trajectory's Y is the cosine distance of their features,

    C[i, j] = 1 - <x_i, y_j> / (max(|x_i|, eps) * max(|y_j|, eps)),   x = f(X), y = f(Y),

and the critic *maximises* the transported cost of a batch of N (learner, expert, plan) pairs:

    L(theta) = -(1 / max(N - 1, 1)) * sum_n sum_ij stop_gradient(P_n)_ij C_n(theta)_ij.

The plans are solved on the host (``ilfo.ot.sinkhorn``, float64) from the costs' values and are
constants: gradients flow only through C, into the learner's features and the expert's. The
divisor N - 1 is the authors' code's (its ``len(episodes) - 1``); with one pair it would be 0, so
ilfo uses max(N - 1, 1).

Where ilfo departs: ``eps`` (1e-12) in the norms, a safety guard the authors' code lacks (a zero
feature vector gives NaN there, cost 1 and finite gradients here); and C is clipped to [0, 2],
the range float32 rounding can step out of by ~1e-7, so that rewards built from it keep their
sign.

The network runs in float32 (the authors' ran in float64; the spec, section 9, allows float32 for
the networks); parameters cast to float64 (under ``jax.enable_x64``) run in float64, which the
tests use for finite differences.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import flax
import jax
import jax.numpy as jnp
import numpy as np
import optax
from flax import serialization, traverse_util

from ilfo.networks import MLP

__all__ = [
    "COSINE_EPS",
    "AdversarialCritic",
    "CriticState",
    "Pair",
    "cosine_cost",
    "critic_arrays",
    "load_critic_arrays",
]

COSINE_EPS = 1e-12
"""Floor of the feature norms in ``cosine_cost`` (the authors' code has none)."""

# Atoms are padded to a multiple of this many rows before the jitted calls, so that episodes of
# many different lengths (standard, terminating episodes) share a few compiled shapes.
_PAD = 64

Pair = tuple[np.ndarray, np.ndarray, np.ndarray]
"""(learner atoms (T, k), expert atoms (M, k), plan (T, M)): one term of the critic's loss."""


def cosine_cost(x: jax.Array, y: jax.Array, eps: float = COSINE_EPS) -> jax.Array:
    """Cosine distances C[i, j] = 1 - <x_i, y_j> / (max(|x_i|, eps) max(|y_j|, eps)), in [0, 2].

    Args:
        x: Features, shape (n, k).
        y: Features, shape (m, k).
        eps: Floor of the norms: a zero vector has cost 1 to everything, with finite gradients.

    Returns:
        Costs, shape (n, m), in the inputs' dtype.
    """
    # The norm's gradient at 0 is NaN, and max(., eps) would multiply it by 0: floor the squared
    # norm instead, whose gradient 2x is 0 there.
    nx = jnp.sqrt(jnp.maximum(jnp.sum(x * x, axis=-1), eps * eps))
    ny = jnp.sqrt(jnp.maximum(jnp.sum(y * y, axis=-1), eps * eps))
    cos = (x / nx[:, None]) @ (y / ny[:, None]).T
    return jnp.clip(1.0 - cos, 0.0, 2.0)


class CriticState(flax.struct.PyTreeNode):
    """The critic's parameters and Adam state (a pytree)."""

    params: Any
    opt_state: optax.OptState


class AdversarialCritic:
    """SIL's critic as pure functions (the configuration closed over).

    Args:
        hidden: Hidden layer widths (ReLU).
        features: Output features (a linear layer).
        lr: Adam's learning rate (other settings: optax's defaults, PyTorch's: betas (0.9,
            0.999), eps 1e-8).
    """

    def __init__(
        self, hidden: Sequence[int] = (128, 128), features: int = 30, lr: float = 5e-4
    ) -> None:
        self.hidden = tuple(hidden)
        self.num_features = features
        self.lr = lr
        self._net = MLP(self.hidden, features, "torch", "relu")

    def init(self, key: jax.Array, atom_dim: int) -> CriticState:
        """Fresh parameters (PyTorch's default initialisation) for atoms of ``atom_dim``, and
        Adam's state."""
        params, opt_state = _init_jit(self._net, self.lr, key, atom_dim)
        return CriticState(params=params, opt_state=opt_state)

    def features(self, params: Any, atoms: jax.Array) -> jax.Array:
        """f_theta(atoms): (n, atom_dim) -> (n, features)."""
        return self._net.apply(params, atoms)

    def cost(self, params: Any, learner_atoms: np.ndarray, expert_atoms: np.ndarray) -> np.ndarray:
        """The cosine cost between the critic's features, (T, M), as float64 numpy for a solve
        (one jitted call, on padded atoms)."""
        dtype = _dtype(params)
        x, y = np.asarray(learner_atoms, dtype), np.asarray(expert_atoms, dtype)
        _check_atoms(x, y)
        cost = _cost_jit(self._net, params, _pad(x), _pad(y))
        return np.asarray(cost, dtype=np.float64)[: len(x), : len(y)]

    def loss(self, params: Any, pairs: Sequence[Pair]) -> jax.Array | float:
        """The critic's loss, -(1 / max(N - 1, 1)) sum_n <stop_gradient(P_n), C_n(params)>,
        as one differentiable expression (no padding, no jit: a reference for tests); 0.0 for
        no pairs."""
        dtype = _dtype(params)
        total: jax.Array | float = 0.0
        for learner, expert, plan in pairs:
            x, y = jnp.asarray(learner, dtype), jnp.asarray(expert, dtype)
            cost = _cost_fn(self._net, params, x, y)
            total = total + jnp.sum(jax.lax.stop_gradient(jnp.asarray(plan, dtype)) * cost)
        return -total / max(len(pairs) - 1, 1)

    def loss_and_grad(self, params: Any, pairs: Sequence[Pair]) -> tuple[float, Any]:
        """The critic's loss (see ``loss``) and its gradient (numpy leaves), pair by pair
        through one jitted call each on padded atoms: pairs of many lengths compile a few
        shapes, not one each."""
        if not pairs:
            raise ValueError("the critic's loss needs at least one (learner, expert, plan) pair")
        dtype, total, grads = _dtype(params), 0.0, None
        for learner, expert, plan in pairs:
            x, y, p = (np.asarray(a, dtype) for a in (learner, expert, plan))
            _check_atoms(x, y)
            if p.shape != (len(x), len(y)):
                raise ValueError(
                    f"plan of shape {p.shape} for {len(x)} learner, {len(y)} expert atoms"
                )
            # Padded rows and columns carry no mass: they add nothing to the value or gradient.
            value, grad = _transported_jit(self._net, params, _pad(x), _pad(y), _pad(p, axes=2))
            total += float(value)
            grad = jax.tree.map(np.asarray, grad)
            grads = grad if grads is None else jax.tree.map(np.add, grads, grad)
        scale = -1.0 / max(len(pairs) - 1, 1)
        return scale * total, jax.tree.map(lambda g: (scale * g).astype(g.dtype), grads)

    def step(self, state: CriticState, pairs: Sequence[Pair]) -> tuple[CriticState, float]:
        """One Adam step on the critic's loss over ``pairs``; returns the new state and the loss
        before the step."""
        loss, grads = self.loss_and_grad(state.params, pairs)
        params, opt_state = _adam_jit(self.lr, grads, state.opt_state, state.params)
        return CriticState(params=params, opt_state=opt_state), loss


def _init_fn(net: MLP, lr: float, key: jax.Array, atom_dim: int) -> tuple[Any, optax.OptState]:
    params = net.init(key, jnp.zeros((1, atom_dim), jnp.float32))
    return params, optax.adam(lr).init(params)


def _cost_fn(net: MLP, params: Any, x: jax.Array, y: jax.Array) -> jax.Array:
    return cosine_cost(net.apply(params, x), net.apply(params, y))


def _transported_fn(net: MLP, params: Any, x: jax.Array, y: jax.Array, plan: jax.Array):
    return jnp.sum(jax.lax.stop_gradient(plan) * _cost_fn(net, params, x, y))


def _adam_fn(lr: float, grads: Any, opt_state: optax.OptState, params: Any):
    updates, opt_state = optax.adam(lr).update(grads, opt_state, params)
    return optax.apply_updates(params, updates), opt_state


# The module (a frozen dataclass) and lr are static: critics of the same settings share code.
_init_jit = jax.jit(_init_fn, static_argnums=(0, 1, 3))
_cost_jit = jax.jit(_cost_fn, static_argnums=0)
_transported_jit = jax.jit(jax.value_and_grad(_transported_fn, argnums=1), static_argnums=0)
_adam_jit = jax.jit(_adam_fn, static_argnums=0)


def critic_arrays(state: CriticState, prefix: str = "critic/") -> dict[str, np.ndarray]:
    """The critic's state as named numpy arrays (``RewardState.arrays``): ``prefix`` followed by
    the leaf's path in flax's state dict, '/'-separated (``critic/params/params/Dense_0/kernel``,
    ``critic/opt_state/0/mu/...``, ``critic/opt_state/0/count``)."""
    flat = traverse_util.flatten_dict(serialization.to_state_dict(state), sep="/")
    return {prefix + name: np.asarray(leaf) for name, leaf in flat.items()}


def load_critic_arrays(
    template: CriticState, arrays: dict[str, np.ndarray], prefix: str = "critic/"
) -> CriticState:
    """The critic state that ``critic_arrays`` wrote, restored into ``template``'s structure.

    Raises:
        ValueError: an array is missing, unexpected, or of another shape than the template's
            (e.g. a critic of other widths, or atoms of another dimension).
    """
    flat = traverse_util.flatten_dict(
        serialization.to_state_dict(template), sep="/", keep_empty_nodes=True
    )
    leaves = {name for name, leaf in flat.items() if leaf is not traverse_util.empty_node}
    given = {name[len(prefix) :] for name in arrays if name.startswith(prefix)}
    if given != leaves:
        missing, extra = sorted(leaves - given), sorted(given - leaves)
        raise ValueError(
            f"critic state does not match this critic: missing {missing[:3]}, "
            f"unexpected {extra[:3]}"
        )
    for name in leaves:
        value = np.asarray(arrays[prefix + name])
        if value.shape != np.shape(flat[name]):
            raise ValueError(
                f"critic state array {prefix + name} has shape {value.shape}, "
                f"this critic's is {np.shape(flat[name])}"
            )
        flat[name] = jnp.asarray(value, dtype=jnp.asarray(flat[name]).dtype)
    restored = traverse_util.unflatten_dict(flat, sep="/")
    return serialization.from_state_dict(template, restored)


def _dtype(params: Any) -> np.dtype:
    """The parameters' dtype (float32; float64 when cast so, under x64, in tests)."""
    return np.dtype(jax.tree.leaves(params)[0].dtype)


def _check_atoms(x: np.ndarray, y: np.ndarray) -> None:
    if x.ndim != 2 or y.ndim != 2 or x.shape[1] != y.shape[1] or not len(x) or not len(y):
        raise ValueError(f"atoms must be non-empty (T, k) and (M, k), got {x.shape} and {y.shape}")


def _padded(n: int) -> int:
    return -(-n // _PAD) * _PAD


def _pad(x: np.ndarray, axes: int = 1) -> np.ndarray:
    """``x`` with zero rows (and columns if ``axes`` is 2) up to a multiple of ``_PAD``, on the
    host (a padding in JAX would compile for every shape)."""
    shape = tuple(_padded(n) if i < axes else n for i, n in enumerate(x.shape))
    out = np.zeros(shape, x.dtype)
    out[tuple(slice(0, n) for n in x.shape)] = x
    return out


def pending_atoms(arrays: dict[str, np.ndarray], k: int, atom_dim: int) -> np.ndarray:
    """The learner atoms (T, atom_dim) of pending episode ``k`` in a reward state's arrays
    (``pending/<k>``, as SIL's and OOPS_adv's ``state()`` write them), checked; a ValueError
    names what is wrong."""
    atoms = arrays.get(f"pending/{k}")
    if atoms is None:
        raise ValueError(f"reward state lists pending episode {k} but has no pending/{k} array")
    atoms = np.asarray(atoms, dtype=np.float64)
    if atoms.ndim != 2 or atoms.shape[1] != atom_dim:
        raise ValueError(
            f"pending episode {k} has atoms of shape {atoms.shape}, expected (T, {atom_dim})"
        )
    return atoms
