"""The SB3 integration: the rows rewritten are exactly each episode's (wrap-around, several
envs ending at different times), rewards equal the episode reward's, the task reward never
reaches the learner, a run is deterministic under a seed."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

sb3 = pytest.importorskip("stable_baselines3")
from stable_baselines3.common.vec_env import DummyVecEnv  # noqa: E402

from ilfo.integrations.sb3 import OTReplayBuffer  # noqa: E402

pytestmark = pytest.mark.integration  # Stable-Baselines3 and torch: trains and relabels

TASK_REWARD = 1e6  # would show anywhere it leaked


class RandomLengthEnv(gym.Env):
    """3-dim observations that drift with the action; episodes of 3-25 steps (terminated or
    truncated at random); every step pays TASK_REWARD. Logs each episode's observations."""

    observation_space = gym.spaces.Box(-np.inf, np.inf, (3,), np.float32)
    action_space = gym.spaces.Box(-1.0, 1.0, (2,), np.float32)

    def __init__(self, seed):
        self.rng = np.random.default_rng(seed)
        self.log = []  # (observations (T + 1, 3), ended) per episode, in order

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.length = int(self.rng.integers(3, 26))
        self.t = 0
        self.obs = self.rng.normal(size=3).astype(np.float32)
        self.log.append([self.obs.copy()])
        return self.obs.copy(), {}

    def step(self, action):
        self.t += 1
        self.obs = (self.obs + 0.1 * np.r_[action, action[0]] + 0.01).astype(np.float32)
        self.log[-1].append(self.obs.copy())
        end = self.t >= self.length
        terminated, truncated = end and self.length % 2 == 0, end and self.length % 2 == 1
        return self.obs.copy(), TASK_REWARD, terminated, truncated, {}


def episode_reward(observations):
    """A deterministic function of the whole episode: each step's distance to the episode's
    mean, so that a wrong row or a wrong episode gives other numbers."""
    steps = observations[1:] - observations.mean(axis=0)
    return -np.linalg.norm(steps, axis=1) - 0.001 * len(observations)


def _train(seed, n_envs=3, buffer_size=120, steps=300):
    envs = [RandomLengthEnv(seed * 10 + j) for j in range(n_envs)]
    vec = DummyVecEnv([lambda e=e: e for e in envs])
    model = sb3.TD3(
        "MlpPolicy",
        vec,
        buffer_size=buffer_size,
        learning_starts=90,
        batch_size=16,
        policy_kwargs={"net_arch": [16, 16]},
        replay_buffer_class=OTReplayBuffer,
        replay_buffer_kwargs={"reward": episode_reward},
        seed=seed,
        device="cpu",
    )
    model.learn(total_timesteps=steps * n_envs)
    return model, envs


def test_rows_rewritten_are_exactly_each_episode():
    model, envs = _train(seed=0)
    buffer = model.replay_buffer
    assert buffer.full  # 300 steps in 40 rows per env: the ring wrapped many times
    assert buffer.ready_count == buffer.ready.sum()
    writes = model.num_timesteps // len(envs)  # steps stored per env column
    for j, env in enumerate(envs):
        # env j's transitions in order, each with its episode's label (None while running)
        stream = []
        for index, observations in enumerate(env.log):
            observations = np.asarray(observations, np.float64)
            running = index == len(env.log) - 1  # auto-reset: every earlier episode has ended
            labels = None if running else episode_reward(observations)
            stream += [(labels, t, observations) for t in range(len(observations) - 1)]
        stream = stream[:writes]
        for k in range(writes - buffer.buffer_size, writes):
            labels, t, observations = stream[k]
            row = k % buffer.buffer_size
            np.testing.assert_array_equal(buffer.observations[row, j], observations[t])
            if labels is None:
                assert not buffer.ready[row, j] and buffer.rewards[row, j] == 0
            else:
                assert buffer.ready[row, j]
                assert buffer.rewards[row, j] == pytest.approx(labels[t], rel=1e-5)


def test_the_task_reward_never_reaches_the_learner():
    model, _ = _train(seed=1, steps=120)
    buffer = model.replay_buffer
    assert buffer.episodes_labelled > 10
    assert np.all(np.abs(buffer.rewards) < TASK_REWARD / 10)
    batch = buffer.sample(512)
    sampled = batch.rewards.numpy().reshape(-1)
    ready = buffer.rewards[buffer.ready]
    assert np.all(np.isin(sampled.astype(np.float32), ready.astype(np.float32)))


def test_deterministic_under_a_seed():
    a, _ = _train(seed=2, steps=100)
    b, _ = _train(seed=2, steps=100)
    np.testing.assert_array_equal(a.replay_buffer.rewards, b.replay_buffer.rewards)
    np.testing.assert_array_equal(a.replay_buffer.ready, b.replay_buffer.ready)
    for pa, pb in zip(a.policy.parameters(), b.policy.parameters(), strict=True):
        np.testing.assert_array_equal(pa.detach().numpy(), pb.detach().numpy())


def test_bad_settings_are_refused_clearly():
    space = gym.spaces.Box(-1, 1, (3,), np.float32)
    act = gym.spaces.Box(-1, 1, (2,), np.float32)
    with pytest.raises(ValueError, match="optimize_memory_usage"):
        OTReplayBuffer(10, space, act, optimize_memory_usage=True, reward=episode_reward)
    with pytest.raises(ValueError, match="flat Box"):
        OTReplayBuffer(10, gym.spaces.Discrete(3), act, reward=episode_reward)
    with pytest.raises(ValueError, match="observation_columns"):
        OTReplayBuffer(10, space, act, reward=episode_reward, observation_columns=4)
    empty = OTReplayBuffer(10, space, act, reward=episode_reward)
    with pytest.raises(ValueError, match="learning_starts"):
        empty.sample(4)
    short = OTReplayBuffer(10, space, act, reward=lambda obs: np.zeros(1))
    short.add(np.zeros((1, 3)), np.zeros((1, 3)), np.zeros((1, 2)), np.ones(1), np.zeros(1), [{}])
    with pytest.raises(ValueError, match="1 rewards for an episode of 2 steps"):
        short.add(
            np.zeros((1, 3)), np.zeros((1, 3)), np.zeros((1, 2)), np.ones(1), np.ones(1), [{}]
        )


@pytest.mark.parametrize("name", ["SAC", "TD3", "CrossQ"])
def test_sbx_algorithms_train_on_the_relabelled_buffer(name):
    """sbx's algorithms fill the buffer, which relabels their episodes, and take gradient steps
    on it (whether they learn is tested on SB3's SAC, below)."""
    sbx = pytest.importorskip("sbx")
    import jax

    envs = [RandomLengthEnv(40 + j) for j in range(2)]
    model = getattr(sbx, name)(
        "MlpPolicy",
        DummyVecEnv([lambda e=e: e for e in envs]),
        buffer_size=200,
        learning_starts=60,
        batch_size=16,
        replay_buffer_class=OTReplayBuffer,
        replay_buffer_kwargs={"reward": episode_reward},
        seed=0,
    )
    before = [np.array(x) for x in jax.tree_util.tree_leaves(model.policy.actor_state.params)]
    model.learn(total_timesteps=300)
    buffer = model.replay_buffer
    assert buffer.episodes_labelled > 10 and buffer.ready.any()
    assert np.all(np.abs(buffer.rewards) < TASK_REWARD / 10)
    assert model._n_updates > 0
    after = jax.tree_util.tree_leaves(model.policy.actor_state.params)
    assert any(not np.array_equal(b, np.asarray(a)) for b, a in zip(before, after, strict=True))


class PointMass(gym.Env):
    """x += 0.1 a for 50 steps from x = 0; the task reward is 0 (only OOPS teaches)."""

    observation_space = gym.spaces.Box(-np.inf, np.inf, (1,), np.float32)
    action_space = gym.spaces.Box(-1.0, 1.0, (1,), np.float32)

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.t, self.x = 0, np.zeros(1, np.float32)
        return self.x.copy(), {}

    def step(self, action):
        self.t += 1
        self.x = (self.x + 0.1 * np.clip(action, -1, 1)).astype(np.float32)
        return self.x.copy(), 0.0, False, self.t >= 50, {}


def test_sac_learns_to_imitate_from_the_relabelled_rewards():
    """An expert that moves right at full speed, observed only; SB3's SAC learning from the
    buffer's OOPS rewards alone halves (and more) its OT distance to the expert within 6,000
    steps (measured: 0.82 for random actions, 0.24 learned)."""
    from ilfo.rewards import OOPS

    oops = OOPS([(0.1 * np.arange(51.0))[:, None]])

    def distance(policy):
        env = PointMass()
        obs, _ = env.reset()
        observations = [obs]
        for _ in range(50):
            obs, *_ = env.step(policy(obs))
            observations.append(obs)
        return oops(np.asarray(observations, np.float64)).distance

    rng = np.random.default_rng(0)
    random_distance = distance(lambda obs: rng.uniform(-1, 1, 1))
    model = sb3.SAC(
        "MlpPolicy",
        PointMass(),
        learning_starts=500,
        replay_buffer_class=OTReplayBuffer,
        replay_buffer_kwargs={"reward": oops},
        policy_kwargs={"net_arch": [32, 32]},
        seed=0,
        device="cpu",
    )
    model.learn(6000)
    learned = distance(lambda obs: model.predict(obs, deterministic=True)[0])
    assert learned < 0.5 * random_distance, (learned, random_distance)


def test_rewards_equal_the_oops_rewards_of_the_episode():
    """With ilfo's OOPS as the episode reward, an ended episode's rows hold exactly
    ``OOPS(demos)(observations).rewards``."""
    from ilfo.rewards import OOPS

    demo = np.cumsum(np.full((31, 3), 0.02), axis=0)
    env = RandomLengthEnv(7)
    model = sb3.TD3(
        "MlpPolicy",
        DummyVecEnv([lambda: env]),
        buffer_size=500,
        learning_starts=200,
        policy_kwargs={"net_arch": [16]},
        replay_buffer_class=OTReplayBuffer,
        replay_buffer_kwargs={"reward": OOPS([demo])},
        seed=0,
        device="cpu",
    )
    model.learn(total_timesteps=150)
    buffer, reference = model.replay_buffer, OOPS([demo])
    row = 0
    for observations in env.log[:-1]:  # every ended episode, in order from row 0
        observations = np.asarray(observations, np.float64)
        steps = len(observations) - 1
        want = reference(observations).rewards
        np.testing.assert_allclose(buffer.rewards[row : row + steps, 0], want, rtol=1e-5)
        assert buffer.ready[row : row + steps, 0].all()
        row += steps
    assert row > 50


def _add(buffer, obs, next_obs, done):
    """One step of one env (observations (d,)) into ``buffer``."""
    buffer.add(obs[None], next_obs[None], np.zeros((1, 2)), np.ones(1), np.array([done]), [{}])


def _episode(buffer, steps, width=3):
    """A whole episode of ``steps`` steps, of distinct observations."""
    for t in range(steps):
        obs = np.full(width, float(t))
        _add(buffer, obs, obs + 1, t == steps - 1)


def test_a_reward_narrower_than_the_observations_is_refused_at_construction():
    """With a time feature appended and no observation_columns, the error comes when the model
    is built (not when the first episode ends, inside learn), and names observation_columns."""
    from ilfo.envs import TimeFeature
    from ilfo.rewards import OOPS, PWIL

    demos = [np.cumsum(np.full((31, 3), 0.02), axis=0)]
    env = TimeFeature(RandomLengthEnv(0), horizon=25)
    for reward in (OOPS(demos), PWIL(demos)):
        kwargs = {"replay_buffer_class": OTReplayBuffer, "device": "cpu"}
        with pytest.raises(ValueError, match="observation_columns=3"):
            sb3.TD3("MlpPolicy", env, replay_buffer_kwargs={"reward": reward}, **kwargs)
        columns = {"reward": reward, "observation_columns": 3}
        model = sb3.TD3("MlpPolicy", env, replay_buffer_kwargs=columns, **kwargs)
        assert model.replay_buffer.observation_columns == 3
    space = gym.spaces.Box(-1, 1, (2,), np.float32)  # narrower than the demos: no columns help
    with pytest.raises(ValueError, match=r"dimension 3.*2 columns"):
        OTReplayBuffer(10, space, space, reward=OOPS(demos))
    space = gym.spaces.Box(-1, 1, (3,), np.float32)  # as wide, but columns cut off
    with pytest.raises(ValueError, match="leave observation_columns None"):
        OTReplayBuffer(10, space, space, reward=OOPS(demos), observation_columns=2)


def test_a_reward_without_obs_dim_that_refuses_the_width_names_observation_columns():
    from ilfo.rewards import OOPS

    oops = OOPS([np.cumsum(np.full((31, 3), 0.02), axis=0)])
    space = gym.spaces.Box(-1, 1, (4,), np.float32)
    act = gym.spaces.Box(-1, 1, (2,), np.float32)
    buffer = OTReplayBuffer(10, space, act, reward=lambda obs: oops(obs).rewards)
    with pytest.raises(ValueError, match="observation_columns"):
        _episode(buffer, 3, width=4)


@pytest.mark.parametrize("columns", [3.0, True, "3"])
def test_observation_columns_must_be_an_int(columns):
    space = gym.spaces.Box(-1, 1, (3,), np.float32)
    act = gym.spaces.Box(-1, 1, (2,), np.float32)
    with pytest.raises(ValueError, match="observation_columns must be an int"):
        OTReplayBuffer(10, space, act, reward=episode_reward, observation_columns=columns)
    buffer = OTReplayBuffer(10, space, act, reward=episode_reward, observation_columns=np.int64(2))
    assert buffer.observation_columns == 2


def test_an_episode_longer_than_the_buffer_warns_once():
    seen = []

    def reward(observations):
        seen.append(observations)
        return np.zeros(len(observations) - 1)

    space = gym.spaces.Box(-1, 1, (3,), np.float32)
    act = gym.spaces.Box(-1, 1, (2,), np.float32)
    buffer = OTReplayBuffer(4, space, act, reward=reward)
    with pytest.warns(UserWarning, match=r"7 steps.*last 4.*larger buffer_size"):
        _episode(buffer, 7)
    np.testing.assert_array_equal(seen[0][:, 0], [3, 4, 5, 6, 7])  # its last 4 steps
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        _episode(buffer, 9)  # once: no second warning
        _episode(buffer, 2)
    assert buffer.ready_count == buffer.ready.sum() == 4


@pytest.mark.parametrize("bad", [np.nan, np.inf])
def test_nan_rewards_are_refused(bad):
    space = gym.spaces.Box(-1, 1, (3,), np.float32)
    act = gym.spaces.Box(-1, 1, (2,), np.float32)
    buffer = OTReplayBuffer(10, space, act, reward=lambda obs: np.r_[0.0, bad, 0.0])
    with pytest.raises(ValueError, match=r"NaN or inf.*episode of 3 steps"):
        _episode(buffer, 3)
    assert buffer.ready_count == 0 and not buffer.ready.any()


def test_an_episode_abandoned_by_a_reset_is_not_glued_onto_the_next():
    """A second learn() resets the envs mid-episode: the next episode is rewarded on its own
    steps, and the abandoned ones stay unready."""
    seen = []

    def reward(observations):
        seen.append(observations[:, 0].copy())
        return np.zeros(len(observations) - 1)

    space = gym.spaces.Box(-np.inf, np.inf, (3,), np.float32)
    act = gym.spaces.Box(-1, 1, (2,), np.float32)
    buffer = OTReplayBuffer(50, space, act, reward=reward)
    for t in range(3):  # abandoned after 3 steps
        _add(buffer, np.full(3, float(t)), np.full(3, t + 1.0), False)
    for t in range(5):  # the reset's episode: it does not start where the last step ended
        _add(buffer, np.full(3, 100.0 + t), np.full(3, 101.0 + t), t == 4)
    np.testing.assert_array_equal(seen[0], [100, 101, 102, 103, 104, 105])
    assert buffer.ready_count == buffer.ready.sum() == 5 and not buffer.ready[:3].any()


def test_reset_empties_the_ready_rows_too():
    """SB3's reset() left them counted: sampling then redrew unready rows forever."""
    space = gym.spaces.Box(-1, 1, (3,), np.float32)
    act = gym.spaces.Box(-1, 1, (2,), np.float32)
    buffer = OTReplayBuffer(10, space, act, reward=episode_reward)
    _episode(buffer, 5)
    assert buffer.ready_count == 5
    buffer.reset()
    _add(buffer, np.zeros(3), np.ones(3), False)
    assert buffer.ready_count == 0 and buffer.episode_steps.tolist() == [1]
    with pytest.raises(ValueError, match="no episode has ended yet"):
        buffer.sample(4)
