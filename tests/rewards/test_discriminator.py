"""The (s, s') discriminator and its reward (GAIfO/DACfO, OPOLO)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from ilfo.rewards import (
    Discriminator,
    DiscriminatorConfig,
    Transitions,
    expert_transitions,
    sample_transitions,
)
from ilfo.rewards.discriminator import gradient_penalty


def _cloud(rng, centre, n=2000, dim=3):
    return Transitions(
        jnp.asarray(rng.normal(centre, 1.0, (n, dim)), jnp.float32),
        jnp.asarray(rng.normal(centre, 1.0, (n, dim)), jnp.float32),
    )


def _train(disc, expert, learner, steps=300, seed=1):
    state = disc.init(jax.random.PRNGKey(0), expert)
    update = jax.jit(disc.update)
    key = jax.random.PRNGKey(seed)
    for _ in range(steps):
        key, k_l, k_e, k_step = jax.random.split(key, 4)
        batch_l = sample_transitions(learner, k_l, disc.batch_size)
        batch_e = sample_transitions(expert, k_e, disc.batch_size)
        state, metrics = update(state, batch_l, batch_e, k_step)
    return state, metrics


def test_discriminator_separates_two_clouds_and_its_reward_orders_them():
    rng = np.random.default_rng(0)
    expert, learner = _cloud(rng, 1.0), _cloud(rng, -1.0)
    disc = Discriminator(DiscriminatorConfig(lr=1e-3))
    state, metrics = _train(disc, expert, learner)
    held_e, held_l = _cloud(rng, 1.0, 500), _cloud(rng, -1.0, 500)
    logits_e = disc.logits(state, held_e.obs, held_e.next_obs)
    logits_l = disc.logits(state, held_l.obs, held_l.next_obs)
    accuracy = 0.5 * (float(jnp.mean(logits_e > 0)) + float(jnp.mean(logits_l < 0)))
    assert accuracy > 0.95
    assert float(metrics["reward_accuracy"]) > 0.95
    r_e = disc.reward(state, held_e.obs, held_e.next_obs)
    r_l = disc.reward(state, held_l.obs, held_l.next_obs)
    assert float(jnp.median(r_e)) > float(jnp.max(jnp.sort(r_l)[: len(r_l) // 2]))
    # -log(1 - D), clipped: positive and bounded by -log(1e-4).
    assert float(jnp.min(r_l)) > 0.0 and float(jnp.max(r_e)) <= -np.log(1e-4) + 1e-4


def test_reward_is_minus_log_one_minus_d():
    rng = np.random.default_rng(1)
    expert = _cloud(rng, 0.0, 50)
    disc = Discriminator(DiscriminatorConfig())
    state = disc.init(jax.random.PRNGKey(0), expert)
    d = jax.nn.sigmoid(disc.logits(state, expert.obs, expert.next_obs))
    expected = -jnp.log(jnp.clip(1.0 - d, 1e-4, 1.0 - 1e-8))
    np.testing.assert_allclose(disc.reward(state, expert.obs, expert.next_obs), expected, 1e-5)


def test_gradient_penalty_equals_a_hand_computation():
    # For a linear logit w.x + b the gradient is w everywhere: penalty (|w| - 1)^2.
    w = jnp.array([3.0, -4.0, 0.0])
    linear = lambda x: x @ w + 0.5  # noqa: E731
    x_e, x_l = jnp.ones((4, 3)), jnp.zeros((4, 3))
    mix = jnp.full((4, 1), 0.3)
    assert float(gradient_penalty(linear, x_e, x_l, mix)) == pytest.approx(16.0)
    # For a quadratic logit |x|^2 / 2 the gradient at x_hat is x_hat: penalty (|x_hat| - 1)^2.
    quad = lambda x: 0.5 * jnp.sum(x**2, axis=-1)  # noqa: E731
    x_e = jnp.array([[2.0, 0.0, 0.0], [0.0, 0.0, 4.0]])
    x_l = jnp.zeros((2, 3))
    mix = jnp.array([[0.5], [0.25]])  # x_hat: (1, 0, 0) and (0, 0, 1)... then 1 and 1
    assert float(gradient_penalty(quad, x_e, x_l, mix)) == pytest.approx(0.0, abs=1e-7)
    mix = jnp.array([[1.0], [1.0]])  # |x_hat| = 2 and 4: ((1)^2 + (3)^2) / 2
    assert float(gradient_penalty(quad, x_e, x_l, mix)) == pytest.approx(5.0)


def test_discriminator_loss_parts_match_their_definitions():
    rng = np.random.default_rng(2)
    expert, learner = _cloud(rng, 0.5, 8), _cloud(rng, -0.5, 8)
    cfg = DiscriminatorConfig(grad_penalty=0.0, entropy_coef=0.0)
    disc = Discriminator(cfg)
    state = disc.init(jax.random.PRNGKey(3), expert)
    loss, parts = disc.loss(state.params, state, learner, expert, jax.random.PRNGKey(0))
    p_e = jax.nn.sigmoid(disc.logits(state, expert.obs, expert.next_obs))
    p_l = jax.nn.sigmoid(disc.logits(state, learner.obs, learner.next_obs))
    bce = -jnp.mean(jnp.log(p_e)) - jnp.mean(jnp.log(1.0 - p_l))
    assert float(loss) == pytest.approx(float(bce), rel=1e-5)
    assert float(parts["reward_loss"]) == pytest.approx(float(bce), rel=1e-5)
    # The entropy bonus (GAIL's: the mean Bernoulli entropy of D over both batches) is
    # subtracted, and the gradient penalty, at points mixed by the key's uniform draws, added.
    p = jnp.concatenate([p_e, p_l])
    entropy = jnp.mean(-p * jnp.log(p) - (1.0 - p) * jnp.log(1.0 - p))
    with_entropy = Discriminator(DiscriminatorConfig(grad_penalty=0.0, entropy_coef=0.1))
    loss, _ = with_entropy.loss(state.params, state, learner, expert, jax.random.PRNGKey(0))
    assert float(loss) == pytest.approx(float(bce - 0.1 * entropy), rel=1e-5)
    penalised = Discriminator(DiscriminatorConfig(grad_penalty=10.0, entropy_coef=0.0))
    key = jax.random.PRNGKey(7)
    loss, parts = penalised.loss(state.params, state, learner, expert, key)
    x_e = penalised._inputs(state, expert.obs, expert.next_obs)
    x_l = penalised._inputs(state, learner.obs, learner.next_obs)
    logit_fn = lambda x: penalised._net.apply(state.params, x)[..., 0]  # noqa: E731
    mix = jax.random.uniform(key, (x_e.shape[0], 1))
    penalty = gradient_penalty(logit_fn, x_e, x_l, mix)
    assert float(penalty) > 0
    assert float(parts["grad_penalty"]) == pytest.approx(float(penalty), rel=1e-5)
    assert float(loss) == pytest.approx(float(bce + 10.0 * penalty), rel=1e-5)


def test_expert_transitions_pairs_consecutive_states_and_checks_sizes():
    demo = np.arange(12, dtype=np.float32).reshape(4, 3)
    t = expert_transitions([demo, demo[:2]])
    np.testing.assert_array_equal(t.obs, np.concatenate([demo[:-1], demo[:1]]))
    np.testing.assert_array_equal(t.next_obs, np.concatenate([demo[1:], demo[1:2]]))
    with pytest.raises(ValueError, match="fewer than a batch of 100"):
        expert_transitions([demo], min_count=100)
    with pytest.raises(ValueError, match="at least two observations"):
        expert_transitions([demo[:1]])
    with pytest.raises(ValueError, match="at least one"):
        expert_transitions([])


def test_config_rejects_bad_values():
    with pytest.raises(ValueError, match="batch_size"):
        DiscriminatorConfig(batch_size=0)
    with pytest.raises(ValueError, match="activation"):
        DiscriminatorConfig(activation="sigmoid")
