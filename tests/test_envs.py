import gymnasium as gym
import numpy as np
import pytest

from ilfo.envs import (
    CONTACT_FORCE_DIMS,
    FULL_OBSERVATION_DIMS,
    drop_contact_forces,
    episode_scores,
    make_env,
    termination_is_finish,
)


def _run(env, seed):
    env.reset(seed=seed)
    rng = np.random.default_rng(seed)
    flags, steps = [], 0
    while True:
        _, _, terminated, truncated, info = env.step(rng.uniform(-1, 1, 3))
        steps += 1
        flags.append(info.get("env_terminated", terminated))
        if terminated or truncated:
            return steps, terminated, truncated, flags


def test_fixed_horizon_ignores_termination_and_records_it():
    steps, terminated, truncated, flags = _run(make_env("Hopper-v5", True, horizon=300), 0)
    assert steps == 300 and truncated and not terminated
    assert any(flags)  # random actions make Hopper fall: the fall is recorded, not obeyed


def test_fixed_horizon_ignores_termination_under_render_wrappers_too():
    """gym.make puts "rgb_array_list"'s RenderCollection outside its own TimeLimit, where the
    termination was once left in force; built only (rendering needs a display library)."""
    from ilfo.envs.wrappers import IgnoreTermination

    env = make_env("Hopper-v5", True, horizon=300, render_mode="rgb_array_list")
    chain = []
    while isinstance(env, gym.Wrapper):
        chain.append(type(env))
        env = env.env
    assert chain[:2] == [gym.wrappers.TimeLimit, IgnoreTermination]
    assert chain.count(gym.wrappers.TimeLimit) == 1 and gym.wrappers.RenderCollection in chain


def test_standard_mode_stops_at_termination():
    steps, terminated, truncated, _ = _run(make_env("Hopper-v5", False, horizon=300), 0)
    assert terminated and not truncated and steps < 300


def test_same_seed_same_episode():
    a = make_env("Hopper-v5", True, horizon=50)
    b = make_env("Hopper-v5", True, horizon=50)
    np.testing.assert_array_equal(a.reset(seed=3)[0], b.reset(seed=3)[0])
    actions = np.random.default_rng(0).uniform(-1, 1, (30, 3))
    for action in actions:  # the same actions from the same start: the same states
        np.testing.assert_array_equal(a.step(action)[0], b.step(action)[0])
    assert not np.array_equal(a.reset(seed=3)[0], b.reset(seed=4)[0])


def test_episode_scores():
    rewards = np.array([1.0, 2.0, 3.0, 4.0])
    fixed, standard = episode_scores(rewards, np.array([False, True, False, True]))
    assert fixed == 4.0  # rewards of terminated steps are zeroed, the episode goes on
    assert standard == 3.0  # stops at (and includes) the first termination
    assert episode_scores(rewards, np.zeros(4, bool)) == (10.0, 10.0)


def test_healthy_angle_range_makes_falls_stricter():
    default = make_env("Hopper-v5", False, horizon=300)
    strict = make_env("Hopper-v5", False, horizon=300, healthy_angle_range=(-0.05, 0.05))
    assert strict.unwrapped._healthy_angle_range == (-0.05, 0.05)
    assert _run(strict, 0)[0] < _run(default, 0)[0]  # same actions, an earlier fall
    with pytest.raises(ValueError, match="not HalfCheetah"):
        make_env("HalfCheetah-v5", healthy_angle_range=(-0.1, 0.1))
    with pytest.raises(ValueError, match="low < high"):
        make_env("Hopper-v5", healthy_angle_range=(0.1, -0.1))


@pytest.mark.parametrize("env_id", ["Ant-v5", "Humanoid-v5"])
def test_without_contact_forces_the_same_states_lack_only_their_last_columns(env_id):
    full, reduced = make_env(env_id, seed=3), make_env(env_id, seed=3, contact_forces=False)
    assert reduced.observation_space.shape[0] == (
        full.observation_space.shape[0] - CONTACT_FORCE_DIMS[env_id]
    )
    obs_full, obs_reduced = [full.reset(seed=3)[0]], [reduced.reset(seed=3)[0]]
    for action in np.random.default_rng(0).uniform(-0.4, 0.4, (60, full.action_space.shape[0])):
        obs_full.append(full.step(action)[0])
        obs_reduced.append(reduced.step(action)[0])
    obs_full = np.array(obs_full)
    assert np.abs(obs_full[:, -CONTACT_FORCE_DIMS[env_id] :]).max() > 0  # touches the floor
    np.testing.assert_array_equal(drop_contact_forces(obs_full, env_id), np.array(obs_reduced))
    with pytest.raises(ValueError, match="not Hopper-v5"):
        make_env("Hopper-v5", contact_forces=False)
    with pytest.raises(ValueError, match="no contact forces"):
        drop_contact_forces(obs_full, "Hopper-v5")
    assert full.observation_space.shape[0] == FULL_OBSERVATION_DIMS[env_id]
    for narrower in (obs_full[:, :10], np.array(obs_reduced)):  # not cut again in their place
        with pytest.raises(ValueError, match=r"not .* full observation"):
            drop_contact_forces(narrower, env_id)


def test_unknown_env_is_a_clear_error():
    with pytest.raises(ValueError, match="unknown environment"):
        make_env("NoSuchEnv-v0")


def test_bipedal_walker_in_fixed_horizon_mode():
    env = make_env("BipedalWalker-v3", True, horizon=120)
    env.reset(seed=0)
    rng = np.random.default_rng(0)
    steps = 0
    while True:
        _, _, terminated, truncated, _ = env.step(rng.uniform(-1, 1, 4))
        steps += 1
        assert not terminated
        if truncated:
            break
    assert steps == 120


def test_a_bipedal_walker_fall_is_not_a_finish():
    # Full power on every joint throws the walker over: gymnasium's fall reward is exactly -100.
    env = make_env("BipedalWalker-v3", True, horizon=400)
    env.reset(seed=0)
    for _ in range(400):
        _, reward, _, _, info = env.step(np.ones(4))
        if info["env_terminated"]:
            break
    assert info["env_terminated"] and reward == -100.0
    assert not termination_is_finish("BipedalWalker-v3", reward)
    assert termination_is_finish("BipedalWalker-v3", 0.4)  # passing the end of the course
    assert not termination_is_finish("Hopper-v5", 0.4)  # a MuJoCo termination is a fall


def test_the_fixed_horizon_wrappers_give_what_the_loop_computes():
    import gymnasium as gym

    from ilfo.envs import FixedHorizonScore, TimeFeature, episode_scores, make_env
    from ilfo.training import agent_observation

    horizon = 50
    env = FixedHorizonScore(TimeFeature(make_env("Hopper-v5", True, horizon=horizon)))
    assert env.observation_space.shape == (12,)
    obs, _ = env.reset(seed=3)
    plain = make_env("Hopper-v5", True, horizon=horizon)
    plain_obs, _ = plain.reset(seed=3)
    rng = np.random.default_rng(0)
    rewards, terminated = [], []
    for t in range(horizon):
        # The env's dtype (float64 for MuJoCo); the agent sees it as float32.
        seen = agent_observation(plain_obs, t, horizon, True)
        np.testing.assert_array_equal(obs.astype(np.float32), seen)
        action = rng.uniform(-1, 1, 3)
        obs, reward, term, trunc, info = env.step(action)
        plain_obs, _, _, _, plain_info = plain.step(action)
        rewards.append(reward)
        terminated.append(plain_info["env_terminated"])
        assert not term and trunc == (t == horizon - 1)
    assert any(terminated)  # random actions fall: the scores differ
    expected = episode_scores(np.array(rewards), np.array(terminated))
    assert (info["fixed_horizon_score"], info["standard_return"]) == expected
    assert obs[-1] == 0.0
    with pytest.raises(ValueError, match="needs a horizon"):
        TimeFeature(gym.make("Hopper-v5", max_episode_steps=None).unwrapped)
