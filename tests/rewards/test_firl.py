"""f-IRL (FKL): the reward gradient, the reward's learning, and the algo end to end."""

import itertools

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from ilfo.rewards import FIRL, FIRLConfig, Transitions, fkl_surrogate
from ilfo.training.build import expert_trajectories

# A 3-state chain, actions left / right (clipped at the ends), s_0 = 0, horizon 3, a uniform
# prior over action sequences: the max-ent trajectory distribution under a tabular reward theta
# at temperature alpha is p(tau) exp(sum_t theta[s_t] / alpha) / Z.
T, ALPHA = 3, 0.5
RHO_E = np.array([0.2, 0.3, 0.5])


def _trajectories():
    out = []
    for actions in itertools.product((-1, 1), repeat=T):
        s, states = 0, []
        for a in actions:
            s = min(max(s + a, 0), 2)
            states.append(s)
        out.append(states)
    return np.array(out)  # (8, T): one per action sequence (each of prior 1/8)


TAUS = _trajectories()
COUNTS = np.stack([(TAUS == s).sum(1) for s in range(3)], axis=1)  # (8, 3): N_s(tau)


def _weights(theta):
    logits = COUNTS @ theta / ALPHA
    w = np.exp(logits - logits.max())
    return w / w.sum()


def _marginal(theta):
    return _weights(theta) @ COUNTS / T


def _fkl(theta):
    rho = _marginal(theta)
    return float(np.sum(RHO_E * np.log(RHO_E / rho)))


def _fd_gradient(theta, eps=1e-5):
    grad = np.zeros(3)
    for k in range(3):
        d = np.zeros(3)
        d[k] = eps
        grad[k] = (_fkl(theta + d) - _fkl(theta - d)) / (2 * eps)
    return grad


def test_fkl_reward_gradient_matches_a_finite_difference():
    theta = np.array([0.3, -0.2, 0.1])
    fd = _fd_gradient(theta)
    u = RHO_E / _marginal(theta)
    a = -(COUNTS @ u)  # -sum_t u(s_t) per trajectory
    w = _weights(theta)
    # Theorem 4.1 exactly (weights rho_theta(tau)): (1 / (alpha T)) Cov(a, N_k).
    cov = (w * a) @ COUNTS - (w @ a) * (w @ COUNTS)
    np.testing.assert_allclose(cov / (ALPHA * T), fd, rtol=1e-6, atol=1e-9)
    # ilfo's surrogate on trajectories sampled from rho_theta: its gradient -> alpha * grad J.
    rng = np.random.default_rng(0)
    idx = rng.choice(len(TAUS), size=400_000, p=w)
    log_ratio = jnp.asarray(np.log(u)[TAUS[idx]], jnp.float32)
    states = jnp.asarray(TAUS[idx])

    def loss(th):
        return fkl_surrogate(log_ratio, th[states])

    grad = np.asarray(jax.grad(loss)(jnp.asarray(theta, jnp.float32)))
    np.testing.assert_allclose(grad, ALPHA * fd, atol=0.02 * np.abs(ALPHA * fd).max())
    # Every trajectory has T states: a constant shift of the reward changes nothing.
    assert abs(fd.sum()) < 1e-8 and abs(grad.sum()) < 1e-3


def _trajs(rng, centre, n, horizon=50, dim=2):
    return jnp.asarray(rng.normal(centre, 0.5, (n, horizon, dim)), jnp.float32)


def test_reward_rises_on_expert_states_relative_to_the_agents():
    rng = np.random.default_rng(1)
    expert, agent = _trajs(rng, 1.0, 4), _trajs(rng, -1.0, 3)
    cfg = FIRLConfig(disc_steps=100, disc_batch_size=64, expert_resample=0, reward_lr=3e-3)
    firl = FIRL(cfg)
    flat = expert.reshape(-1, 2)
    state = firl.init(jax.random.PRNGKey(0), Transitions(flat, flat))
    update = jax.jit(firl.update_from_rollouts)

    def gap(s):
        r_e = firl.reward(s, expert.reshape(-1, 2), None)
        r_a = firl.reward(s, agent.reshape(-1, 2), None)
        return float(jnp.mean(r_e) - jnp.mean(r_a))

    before = gap(state)
    key = jax.random.PRNGKey(2)
    for _ in range(30):
        key, k = jax.random.split(key)
        state, metrics = update(state, agent, expert, k)
    assert float(metrics["reward_accuracy"]) > 0.95  # the density ratio tells them apart
    assert gap(state) > before + 0.1


def test_rewards_are_clipped_and_of_the_state_before_the_transition():
    firl = FIRL(FIRLConfig(reward_clip=0.01))
    x = jnp.asarray(np.random.default_rng(0).normal(0, 100, (20, 3)), jnp.float32)
    state = firl.init(jax.random.PRNGKey(0), Transitions(x, x))
    r = firl.reward(state, x, -x)
    assert float(jnp.max(jnp.abs(r))) <= 0.01
    np.testing.assert_array_equal(r, firl.reward(state, x, x * 0))


def test_expert_trajectories_take_the_horizons_states_and_refuse_short_demos():
    demo = np.arange(22, dtype=np.float32).reshape(11, 2)
    out = expert_trajectories([demo, demo], horizon=4)
    assert out.shape == (2, 4, 2)
    np.testing.assert_array_equal(out[0], demo[1:5])
    with pytest.raises(ValueError, match="fewer than the episode horizon"):
        expert_trajectories([demo], horizon=20)


def test_config_rejects_bad_values():
    with pytest.raises(ValueError, match="rollouts"):
        FIRLConfig(rollouts=0)
    with pytest.raises(ValueError, match="reward_hidden"):
        FIRLConfig(reward_hidden=())
