"""Tests of the episode-aware replay buffer (ilfo.replay)."""

from __future__ import annotations

import jax
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ilfo.replay import ReplayBuffer, ReplayData, sample_batch

OBS_DIM, ACT_DIM = 3, 2


def make_episode(length: int, offset: float = 0.0):
    """Episode whose values encode (offset + step) so that slots can be checked by value."""
    t = np.arange(length + 1, dtype=np.float32) + offset
    obs = np.repeat(t[:, None], OBS_DIM, axis=1) * np.array([1.0, 2.0, 3.0], np.float32)
    act = np.repeat(t[:-1, None], ACT_DIM, axis=1)
    rew = t[:-1] * 10.0
    return obs, act, rew


def test_insert_fields_and_bookkeeping():
    buf = ReplayBuffer(capacity=20, obs_dim=OBS_DIM, action_dim=ACT_DIM)
    obs, act, rew = make_episode(5)
    ep = buf.add_episode(obs, act, rew, terminated=True)
    assert ep == 0 and buf.size == 5 and buf.ptr == 5 and len(buf) == 5
    assert buf.episodes == {0: (0, 5)}
    data = jax.tree.map(np.asarray, buf.data)
    np.testing.assert_array_equal(data.obs[:5], obs[:-1])
    np.testing.assert_array_equal(data.next_obs[:5], obs[1:])
    np.testing.assert_array_equal(data.action[:5], act)
    np.testing.assert_array_equal(data.reward[:5], rew)
    np.testing.assert_array_equal(data.not_done[:5], [1, 1, 1, 1, 0])
    np.testing.assert_array_equal(data.obs[5:], 0.0)  # untouched slots

    ep = buf.add_episode(*make_episode(3, offset=100.0))  # truncated: keeps bootstrapping
    assert ep == 1 and buf.size == 8 and buf.episodes[1] == (5, 3)
    np.testing.assert_array_equal(np.asarray(buf.data.not_done[5:8]), [1, 1, 1])

    back = buf.episode(0)
    np.testing.assert_array_equal(back["observations"], obs)
    np.testing.assert_array_equal(back["actions"], act)
    np.testing.assert_array_equal(back["rewards"], rew)


def test_wrap_around_and_eviction():
    buf = ReplayBuffer(capacity=10, obs_dim=OBS_DIM, action_dim=ACT_DIM)
    episodes = [make_episode(4, offset=100.0 * i) for i in range(4)]
    for e in episodes[:2]:
        buf.add_episode(*e)
    assert buf.episodes == {0: (0, 4), 1: (4, 4)} and buf.ptr == 8

    buf.add_episode(*episodes[2])  # slots 8, 9, 0, 1: overwrites part of episode 0
    assert buf.episodes == {1: (4, 4), 2: (8, 4)}
    assert buf.size == 10 and buf.ptr == 2
    rewards = np.asarray(buf.data.reward)
    np.testing.assert_array_equal(rewards[[8, 9, 0, 1]], episodes[2][2])
    np.testing.assert_array_equal(rewards[2:4], episodes[0][2][2:])  # leftovers of episode 0
    back = buf.episode(2)
    np.testing.assert_array_equal(back["observations"], episodes[2][0])

    buf.add_episode(*episodes[3])  # slots 2..5: evicts episode 1 as well
    assert buf.episodes == {2: (8, 4), 3: (2, 4)} and buf.ptr == 6
    with pytest.raises(KeyError):
        buf.episode(1)


def test_episode_as_long_as_capacity():
    buf = ReplayBuffer(capacity=6, obs_dim=OBS_DIM, action_dim=ACT_DIM)
    buf.add_episode(*make_episode(4))
    buf.add_episode(*make_episode(6, offset=50.0))  # overwrites everything, starts at slot 4
    assert buf.episodes == {1: (4, 6)} and buf.size == 6 and buf.ptr == 4
    np.testing.assert_array_equal(buf.episode(1)["rewards"], make_episode(6, 50.0)[2])
    with pytest.raises(ValueError):
        buf.add_episode(*make_episode(7))


def test_shape_validation():
    buf = ReplayBuffer(capacity=10, obs_dim=OBS_DIM, action_dim=ACT_DIM)
    obs, act, rew = make_episode(4)
    with pytest.raises(ValueError):
        buf.add_episode(obs[:-1], act, rew)  # needs T+1 observations
    with pytest.raises(ValueError):
        buf.add_episode(obs, act, rew[:-1])
    with pytest.raises(ValueError):
        buf.add_episode(obs, act[:, :1], rew)


def test_relabel_bookkeeping():
    buf = ReplayBuffer(capacity=12, obs_dim=OBS_DIM, action_dim=ACT_DIM)
    ids = [buf.add_episode(*make_episode(4)[:2]) for _ in range(2)]  # rewards unknown yet
    np.testing.assert_array_equal(np.asarray(buf.data.reward), 0.0)
    third = buf.add_episode(*make_episode(3, offset=7.0))
    buf.relabel(ids, [np.full(4, 1.5), np.full(4, -2.0)])
    rewards = np.asarray(buf.data.reward)
    np.testing.assert_array_equal(rewards[:4], 1.5)
    np.testing.assert_array_equal(rewards[4:8], -2.0)
    np.testing.assert_array_equal(rewards[8:11], make_episode(3, offset=7.0)[2])  # untouched
    np.testing.assert_array_equal(buf.episode(ids[1])["rewards"], -2.0)

    with pytest.raises(ValueError):
        buf.relabel([third], [np.zeros(4)])  # wrong length
    with pytest.raises(ValueError):
        buf.relabel([third], [])
    buf.add_episode(*make_episode(4))  # slots 11, 0, 1, 2: evicts episode 0
    with pytest.raises(KeyError):
        buf.relabel([ids[0]], [np.zeros(4)])
    buf.relabel([], [])  # no-op


def test_relabel_across_wrap():
    buf = ReplayBuffer(capacity=5, obs_dim=OBS_DIM, action_dim=ACT_DIM)
    buf.add_episode(*make_episode(3))
    ep = buf.add_episode(*make_episode(3)[:2])  # slots 3, 4, 0
    buf.relabel([ep], [np.array([1.0, 2.0, 3.0])])
    np.testing.assert_array_equal(np.asarray(buf.data.reward)[[3, 4, 0]], [1.0, 2.0, 3.0])


@pytest.mark.parametrize("wrapped", [False, True])
def test_save_load_round_trip(tmp_path, wrapped):
    buf = ReplayBuffer(capacity=10, obs_dim=OBS_DIM, action_dim=ACT_DIM)
    for i in range(4 if wrapped else 2):
        buf.add_episode(*make_episode(4, offset=10.0 * i), terminated=i % 2 == 0)
    path = tmp_path / "replay.npz"
    buf.save(path)
    with np.load(path, allow_pickle=False) as f:  # a plain npz, no pickled objects
        assert int(f["schema_version"]) == 1
    loaded = ReplayBuffer.load(path)
    assert (loaded.capacity, loaded.obs_dim, loaded.action_dim) == (10, OBS_DIM, ACT_DIM)
    assert (loaded.size, loaded.ptr, loaded.num_episodes) == (buf.size, buf.ptr, buf.num_episodes)
    assert list(loaded.episodes.items()) == list(buf.episodes.items())  # order kept
    for a, b in zip(loaded.data, buf.data, strict=True):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))

    # Both continue identically.
    for b in (buf, loaded):
        b.add_episode(*make_episode(3, offset=99.0))
    assert loaded.episodes == buf.episodes
    for a, b in zip(loaded.data, buf.data, strict=True):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))


def test_sampling_respects_size():
    buf = ReplayBuffer(capacity=100, obs_dim=OBS_DIM, action_dim=ACT_DIM)
    with pytest.raises(ValueError):
        buf.sample(jax.random.PRNGKey(0), 4)
    buf.add_episode(*make_episode(7))  # rewards 0, 10, ..., 60 in slots 0..6
    batch = buf.sample(jax.random.PRNGKey(0), 2000)
    assert isinstance(batch, ReplayData)
    assert batch.obs.shape == (2000, OBS_DIM) and batch.reward.shape == (2000,)
    rewards = np.asarray(batch.reward)
    assert set(np.unique(rewards)) == set(np.arange(7) * 10.0)  # all filled slots, no others
    # Rows stay consistent: obs, action and reward of one transition travel together.
    np.testing.assert_array_equal(np.asarray(batch.action)[:, 0] * 10.0, rewards)

    # Jittable with a traced size.
    sample = jax.jit(sample_batch, static_argnums=3)
    batch = sample(buf.data, 3, jax.random.PRNGKey(1), 500)
    assert np.asarray(batch.reward).max() <= 20.0


@settings(max_examples=25, deadline=None)
@given(
    capacity=st.integers(3, 12),
    lengths=st.lists(st.integers(1, 12), min_size=1, max_size=8),
)
def test_ring_matches_naive_model(capacity, lengths):
    """Contents and bookkeeping agree with a slot-by-slot Python model of the ring."""
    lengths = [min(t, capacity) for t in lengths]
    buf = ReplayBuffer(capacity=capacity, obs_dim=OBS_DIM, action_dim=ACT_DIM)
    slots = [None] * capacity  # (episode, step) per slot
    ptr = 0
    for ep, t in enumerate(lengths):
        assert buf.add_episode(*make_episode(t, offset=1000.0 * ep)) == ep
        for k in range(t):
            slots[(ptr + k) % capacity] = (ep, k)
        ptr = (ptr + t) % capacity
    assert buf.ptr == ptr
    assert buf.size == sum(s is not None for s in slots)
    expected_reward = np.array(
        [0.0 if s is None else (1000.0 * s[0] + s[1]) * 10.0 for s in slots], np.float32
    )
    np.testing.assert_array_equal(np.asarray(buf.data.reward), expected_reward)
    # Live episodes are exactly those with all their steps still in place.
    live = {ep for ep, t in enumerate(lengths) if all((ep, k) in slots for k in range(t))}
    assert set(buf.episodes) == live
    for ep in live:
        np.testing.assert_array_equal(
            buf.episode(ep)["observations"], make_episode(lengths[ep], 1000.0 * ep)[0]
        )
