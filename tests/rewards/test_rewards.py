import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ilfo import demos as demo_io
from ilfo.rewards import OOPS, PWIL, OOPSConfig, PWILConfig, Standardizer, expert_transitions


def _episode(length=40, dim=5, seed=0, scale=1.0):
    rng = np.random.default_rng(seed)
    return np.cumsum(rng.normal(scale=scale, size=(length + 1, dim)), axis=0)


def test_standardizer_follows_the_reference_recipe():
    demos = [_episode(seed=1), _episode(seed=2)]
    demos[0][:, 2] = 7.0  # constant in demo 0 ...
    demos[1][:, 2] = 7.0  # ... and in demo 1: zero std -> 1
    states = np.concatenate([d[:-1] for d in demos])
    std = states.std(axis=0, ddof=1)
    std[2] = 1.0
    std = np.maximum(std, 0.33)
    fitted = Standardizer.from_demos(demos)
    np.testing.assert_allclose(fitted.mean, states.mean(axis=0))
    np.testing.assert_allclose(fitted.scale, 3 * std + 1e-8)
    # A constant whose float64 mean rounds (0.1 x 1000: std ~1e-17, not 0) is constant too:
    # PWIL's unfloored scale would otherwise blow its column's differences up by 1e17.
    demos[0][:, 2] = demos[1][:, 2] = 0.1
    pwil = Standardizer.from_demos(demos, std_factor=1.0, std_floor=0.0, eps=0.0)
    assert pwil.scale[2] == 1.0


@pytest.mark.parametrize("solver", ["sinkhorn", "emd", "greedy"])
@pytest.mark.parametrize("atoms", ["transitions", "states"])
def test_rewards_sum_to_minus_scale_times_transport_cost(solver, atoms):
    demo, learner = _episode(seed=3), _episode(seed=4)
    out = OOPS([demo], OOPSConfig(solver=solver, atoms=atoms))(learner)
    num_steps = len(learner) - 1
    scale = 5.0 * num_steps / np.sqrt(demo.shape[1])
    assert out.rewards.shape == (num_steps,)
    assert out.rewards.sum() == pytest.approx(-scale * out.distance, rel=1e-12)
    assert (out.rewards <= 0).all()


def _reference_atoms(demo, episode, atoms):
    """The paper's recipe written out: states standardised by the demo's (not the episode's)
    mean and 3 max(std, 0.33) + 1e-8, then (s_t, s_t+1) or s_t+1 per step."""
    states = demo[:-1]
    scale = 3 * np.maximum(states.std(axis=0, ddof=1), 0.33) + 1e-8
    out = []
    for e in (episode, demo):
        z = (e - states.mean(axis=0)) / scale
        out.append(np.concatenate([z[:-1], z[1:]], axis=1) if atoms == "transitions" else z[1:])
    return out


_REFERENCE_COSTS = {
    "sqrt_euclidean": lambda x, y: np.sqrt(np.linalg.norm(x[:, None] - y[None], axis=2)),
    "euclidean": lambda x, y: np.linalg.norm(x[:, None] - y[None], axis=2),
    "sqeuclidean": lambda x, y: np.sum((x[:, None] - y[None]) ** 2, axis=2),
}


@pytest.mark.parametrize("metric", sorted(_REFERENCE_COSTS))
@pytest.mark.parametrize("atoms", ["transitions", "states"])
def test_rewards_against_an_independent_computation(metric, atoms):
    """Reward t is minus the scaled cost that row t transports, computed here from scratch:
    under exact OT of two equal-length uniform measures the plan is an optimal assignment
    (scipy's), 1/T each; Sinkhorn's plan is POT's at the same lambda."""
    from scipy.optimize import linear_sum_assignment

    import ot as pot

    demo, learner = _episode(seed=3), _episode(seed=4)
    x, y = _reference_atoms(demo, learner, atoms)
    cost = _REFERENCE_COSTS[metric](x, y)
    num_steps = len(learner) - 1
    scale = 5.0 * num_steps / np.sqrt(demo.shape[1])
    rows, cols = linear_sum_assignment(cost)
    exact = OOPS([demo], OOPSConfig(solver="emd", atoms=atoms, metric=metric))(learner)
    np.testing.assert_allclose(exact.rewards[rows], -scale * cost[rows, cols] / num_steps,
                               rtol=1e-10, atol=1e-12)  # fmt: skip
    uniform = np.full(num_steps, 1 / num_steps)
    plan = pot.sinkhorn(uniform, uniform, cost, 0.05, method="sinkhorn_log", stopThr=1e-13,
                        numItermax=100_000)  # fmt: skip
    entropic = OOPS([demo], OOPSConfig(atoms=atoms, metric=metric, tol=1e-12, max_iter=100_000))
    np.testing.assert_allclose(entropic(learner).rewards, -scale * (plan * cost).sum(axis=1),
                               rtol=1e-6)  # fmt: skip


def test_the_expert_itself_gets_zero_reward_under_exact_ot():
    demo = _episode(seed=5)
    out = OOPS([demo], OOPSConfig(solver="emd"))(demo)
    np.testing.assert_allclose(out.rewards, 0.0, atol=1e-12)
    sinkhorn_out = OOPS([demo])(demo)
    far = OOPS([demo])(_episode(seed=6, scale=3.0))
    assert sinkhorn_out.distance < 0.2 * far.distance


@settings(max_examples=25, deadline=None)
@given(st.integers(0, 10_000))
def test_rewards_are_invariant_to_permuting_expert_atoms(seed):
    demo, learner = _episode(length=25, seed=7), _episode(length=25, seed=8)
    rewarder = OOPS([demo])
    base = rewarder(learner).rewards
    perm = np.random.default_rng(seed).permutation(len(rewarder.expert_atoms[0]))
    rewarder.expert_atoms[0] = rewarder.expert_atoms[0][perm]
    np.testing.assert_allclose(rewarder(learner).rewards, base, rtol=1e-7, atol=1e-10)


def test_demo_selection_modes():
    demos = [_episode(seed=10), _episode(seed=11), _episode(seed=12)]
    learner = demos[1] + 1e-3
    nearest = OOPS(demos, OOPSConfig(demo_selection="nearest"))(learner)
    assert nearest.demo_index == 1
    pooled = OOPS(demos, OOPSConfig(demo_selection="pooled"))(learner)
    assert pooled.demo_index is None
    assert pooled.coupling.plan.shape == (40, 120)
    draws = [OOPS(demos, OOPSConfig(seed=3))(learner).demo_index for _ in range(2)]
    assert draws[0] == draws[1]  # same seed, same demo
    rewarder = OOPS(demos, OOPSConfig(seed=3))
    assert len({rewarder(learner).demo_index for _ in range(30)}) == 3


def test_warm_start_gives_the_same_rewards():
    demo = _episode(seed=13)
    learners = [_episode(seed=14), _episode(seed=14) + 0.01]
    cold = OOPS([demo])
    warm = OOPS([demo], OOPSConfig(warm_start=True))
    for learner in learners:
        warm_out, cold_out = warm(learner), cold(learner)
        np.testing.assert_allclose(warm_out.rewards, cold_out.rewards, atol=1e-6)
    # The second episode starts from the first's potentials: fewer iterations, not a cold start.
    assert warm_out.coupling.iterations < cold_out.coupling.iterations


def test_a_warm_start_saved_against_other_demos_is_dropped_not_a_failure():
    learner = _episode(seed=14)
    saved = OOPS([_episode(length=30, seed=13)], OOPSConfig(warm_start=True))
    saved(learner)
    other = OOPS([_episode(seed=13)], OOPSConfig(warm_start=True))  # a 40-step demo
    other.load_state(saved.state())
    cold = OOPS([_episode(seed=13)])
    np.testing.assert_allclose(other(learner).rewards, cold(learner).rewards, atol=1e-6)


def test_episodes_of_other_lengths_than_the_demo():
    out = OOPS([_episode(length=50, seed=15)])(_episode(length=17, seed=16))
    assert out.rewards.shape == (17,)
    assert out.coupling.plan.shape == (17, 50)


def test_pwil_rewards_the_expert_with_alpha():
    demo = _episode(seed=20)
    out = PWIL([demo])(demo)
    np.testing.assert_allclose(out.rewards, 5.0)
    far = PWIL([demo])(_episode(seed=21, scale=2.0)).rewards
    assert ((far > 0) & (far < 5.0)).all()


def test_pwil_horizon_gives_short_episodes_less_mass():
    demo = _episode(length=40, seed=22)
    out = PWIL([demo], PWILConfig(horizon=40))(demo[:11])
    assert out.coupling.plan.sum() == pytest.approx(10 / 40)
    with pytest.raises(ValueError, match="horizon"):
        PWIL([demo], PWILConfig(horizon=5))(demo)


def test_pwil_subsample_keeps_every_kth_state_from_a_seeded_offset():
    demos = [_episode(length=40, seed=23), _episode(length=40, seed=24)]
    full = PWIL(demos)
    assert len(full.expert_atoms) == 80
    offsets = set()
    for seed in range(8):
        pwil = PWIL(demos, PWILConfig(subsample=4, seed=seed))
        assert len(pwil.expert_atoms) == 20  # 10 of each demo's 40 states
        first, second = pwil.expert_atoms[:10], pwil.expert_atoms[10:]
        k = int(np.flatnonzero((full.expert_atoms[:40] == first[0]).all(axis=1))[0])
        np.testing.assert_array_equal(first, full.expert_atoms[k:40:4])
        k2 = int(np.flatnonzero((full.expert_atoms[40:] == second[0]).all(axis=1))[0])
        np.testing.assert_array_equal(second, full.expert_atoms[40 + k2 : 80 : 4])
        offsets.add(k)
        again = PWIL(demos, PWILConfig(subsample=4, seed=seed)).expert_atoms
        np.testing.assert_array_equal(pwil.expert_atoms, again)  # the seed fixes the offsets
    assert len(offsets) > 1
    short = PWIL([_episode(length=3, seed=25)], PWILConfig(subsample=20, seed=1))
    assert len(short.expert_atoms) == 1  # a demo shorter than the step keeps one state
    rewards = PWIL(demos, PWILConfig(subsample=4))(_episode(length=40, seed=26)).rewards
    assert rewards.shape == (40,) and np.isfinite(rewards).all()


def test_pwil_kernel_dim_sets_the_kernel_width():
    demo, learner = _episode(seed=27), _episode(seed=28, scale=1.5)
    default = PWIL([demo])(learner)
    costs = default.coupling.row_costs
    np.testing.assert_allclose(default.rewards, 5.0 * np.exp(-5.0 * 40 / np.sqrt(5) * costs))
    wide = PWIL([demo], PWILConfig(kernel_dim=9))(learner)
    np.testing.assert_allclose(wide.rewards, 5.0 * np.exp(-5.0 * 40 / 3.0 * costs))
    assert (wide.rewards >= default.rewards).all()


@pytest.mark.parametrize(
    "bad",
    [
        {"subsample": 0},
        {"subsample": 2.5},  # would fail later as a slice step
        {"kernel_dim": 0},
        {"horizon": 0},
        {"alpha": float("nan")},  # NaN rewards
        {"beta": float("inf")},
        {"beta": 0.0},
    ],
)
def test_pwil_config_refuses_bad_values(bad):
    with pytest.raises(ValueError, match=next(iter(bad))):
        PWILConfig(**bad)


def test_the_trainer_sets_pwil_seed():
    from ilfo.training import TrainConfig

    assert TrainConfig(algo="pwil-td3", seed=3).part_config("pwil").seed == 3


@pytest.mark.parametrize("make", [OOPS, PWIL])
@pytest.mark.parametrize(
    ("episode", "match"),
    [
        (np.full((10, 5), np.nan), "NaN or inf"),
        (np.full((10, 5), np.inf), "NaN or inf"),
        (np.zeros(10), "2-D"),
        (np.zeros((10, 5, 1)), "2-D"),
        (np.zeros((10, 4)), "dimension 4"),
        (np.zeros((0, 5)), "at least 2 observations"),
        (np.zeros((1, 5)), "at least 2 observations"),
    ],
)
def test_bad_learner_episodes(make, episode, match):
    rewarder = make([_episode(seed=30)])
    with pytest.raises(ValueError, match=match):
        rewarder(episode)


@pytest.mark.parametrize("make", [OOPS, PWIL])
def test_bad_demos(make):
    with pytest.raises(ValueError, match="at least one"):
        make([])
    with pytest.raises(ValueError, match="different observation dimensions"):
        make([_episode(dim=5), _episode(dim=6)])
    with pytest.raises(ValueError, match="demo 1 contains NaN"):
        make([_episode(), np.full((5, 5), np.nan)])
    with pytest.raises(ValueError, match="at least 2 observations"):
        make([np.zeros((1, 5))])


@pytest.mark.parametrize("make", [OOPS, PWIL, expert_transitions])
def test_demos_given_as_files_are_a_type_error_saying_what_to_pass(make, tmp_path):
    path = tmp_path / "demos.npz"
    demo_io.save(path, [demo_io.Episode(_episode()), demo_io.Episode(_episode(seed=1))], "")
    loaded = demo_io.load(path)
    for given_as in (str(path), path):
        with pytest.raises(TypeError, match=r"not the file name .*demos\.npz.*ilfo\.demos\.load"):
            make(given_as)
    with pytest.raises(TypeError, match=r"not a DemoFile: pass \[e\.observations for e in"):
        make(loaded)
    with pytest.raises(TypeError, match="demo 1 is an Episode, not an array"):
        make([_episode(), loaded.episodes[1]])
    kind = type(path).__name__  # PosixPath or WindowsPath
    with pytest.raises(TypeError, match=rf"demo 0 is a {kind}, not an array.*ilfo\.demos\.load"):
        make([path])
    with pytest.raises(TypeError, match=r"a list of arrays of observations .* got int"):
        make(3)
    # What the messages say to pass is what the reward takes.
    observations = [e.observations for e in loaded.episodes]
    assert make(observations) is not None


@pytest.mark.parametrize("make", [OOPS, PWIL])
def test_demos_that_are_not_numbers_are_a_type_error(make):
    with pytest.raises(TypeError, match=r"demo 1 is not an array of numbers \(a dict"):
        make([_episode(), {"observations": _episode()}])
    with pytest.raises(TypeError, match=r"demo 0 is not an array of numbers \(a list"):
        make([[[0.0, 1.0], [2.0]]])  # ragged
    # A generator of arrays is still read, its items checked as they come.
    assert make(d for d in [_episode(), _episode(seed=1)]).obs_dim == 5


def test_bad_config():
    with pytest.raises(ValueError, match="solver"):
        OOPSConfig(solver="hungarian")
    with pytest.raises(ValueError, match="reg"):
        OOPSConfig(reg=0.0)
    # Refused when the config is made, not at a run's first solve (after its directory is made).
    for bad in ({"reg": float("inf")}, {"tol": 0.0}, {"reward_scale": float("nan")}):
        with pytest.raises(ValueError, match=f"{next(iter(bad))} must be positive and finite"):
            OOPSConfig(**bad)
    for max_iter in (0, 100.5, True):
        with pytest.raises(ValueError, match="max_iter must be an int >= 1"):
            OOPSConfig(max_iter=max_iter)
    with pytest.raises(ValueError, match="demo_selection"):
        OOPSConfig(demo_selection="best")
    with pytest.raises(TypeError, match="config must be an OOPSConfig, got dict"):
        OOPS([_episode()], {"reg": 0.1})
    with pytest.raises(TypeError, match="config must be a PWILConfig, got OOPSConfig"):
        PWIL([_episode()], OOPSConfig())
    with pytest.raises(ValueError, match="unknown metric"):
        OOPS([_episode()], OOPSConfig(metric="manhattan"))(_episode())


def test_time_options_against_an_independent_computation():
    """The authors' ``use_time_index`` and ``use_tcot``, written out from their definitions:
    2 * time-to-go / T appended to each standardised state; each cost times 1 + |i/n - j/m|.
    Under exact OT of equal-length uniform measures the plan is scipy's optimal assignment."""
    from scipy.optimize import linear_sum_assignment

    demo, learner = _episode(length=30, seed=11), _episode(length=30, seed=12)
    states = demo[:-1]
    scale = 3 * np.maximum(states.std(axis=0, ddof=1), 0.33) + 1e-8
    steps = len(demo) - 1
    time_to_go = 2.0 * (steps - np.arange(steps + 1)) / steps

    def atoms(e, with_time):
        z = (e - states.mean(axis=0)) / scale
        if with_time:
            z = np.concatenate([z, time_to_go[:, None]], axis=1)
        return np.concatenate([z[:-1], z[1:]], axis=1)

    for time_index, weighted in ((True, False), (False, True), (True, True)):
        x, y = atoms(learner, time_index), atoms(demo, time_index)
        cost = np.sqrt(np.linalg.norm(x[:, None] - y[None], axis=2))
        if weighted:
            i = np.arange(steps) / steps
            cost = cost * (1 + np.abs(i[:, None] - i[None, :]))
        rows, cols = linear_sum_assignment(cost)
        config = OOPSConfig(solver="emd", time_index=time_index, time_weighted_cost=weighted)
        out = OOPS([demo], config)(learner)
        np.testing.assert_allclose(out.distance, cost[rows, cols].mean(), rtol=1e-10)


def test_time_index_tells_a_reversed_walk_from_the_demo():
    # Without the time index OT matches states in any order: the demo's states visited
    # backwards are nearly free. With it, each step is matched near its own time.
    demo = _episode(length=40, seed=13)
    backwards = demo[::-1].copy()
    plain = OOPS([demo], OOPSConfig(solver="emd", atoms="states"))
    timed = OOPS([demo], OOPSConfig(solver="emd", atoms="states", time_index=True))
    assert timed(demo).distance == pytest.approx(0.0, abs=1e-12)
    assert timed(backwards).distance > 3 * plain(backwards).distance


def test_exponential_kernel_against_an_independent_computation():
    """alpha * exp(-beta * T / sqrt(d) * c_t), c_t the cost step t transports at mass 1/T; under
    exact OT of equal-length uniform measures the plan is scipy's optimal assignment."""
    from scipy.optimize import linear_sum_assignment

    demo, learner = _episode(length=30, seed=21), _episode(length=30, seed=22)
    states = demo[:-1]
    scale = 3 * np.maximum(states.std(axis=0, ddof=1), 0.33) + 1e-8

    def atoms(e):
        z = (e - states.mean(axis=0)) / scale
        return np.concatenate([z[:-1], z[1:]], axis=1)

    cost = np.sqrt(np.linalg.norm(atoms(learner)[:, None] - atoms(demo)[None], axis=2))
    rows, cols = linear_sum_assignment(cost)
    step_cost = cost[rows, cols] / np.sqrt(demo.shape[1])  # T * (1/T) per sqrt(d)
    config = OOPSConfig(solver="emd", kernel="exponential", reward_scale=2.0, kernel_rate=3.0)
    out = OOPS([demo], config)(learner)
    np.testing.assert_allclose(out.rewards, 2.0 * np.exp(-3.0 * step_cost), rtol=1e-10)
    linear = OOPS([demo], OOPSConfig(solver="emd", reward_scale=2.0))(learner)
    np.testing.assert_allclose(linear.rewards, -2.0 * step_cost, rtol=1e-10)
    assert out.distance == pytest.approx(linear.distance, rel=1e-12)  # the coupling is shared


def test_unknown_kernel_is_refused():
    with pytest.raises(ValueError, match="unknown kernel"):
        OOPSConfig(kernel="gaussian")
