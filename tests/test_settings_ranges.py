"""Declared ranges and types of every setting (``ilfo.ranges``): a bad value, given as a flag or
in a settings file, is a one-line error that names the setting, before a run directory exists;
and whatever a config is given, it either holds a value in its declared range or refuses it
with a ValueError (never a TypeError, an OverflowError, or an accepted NaN)."""

import dataclasses
import json
import math
import pickle
import typing
from pathlib import Path

import jax.numpy as jnp
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from ilfo.agents import SACConfig, TD3Config
from ilfo.agents.td7 import TD7Config
from ilfo.algos import ALGOS
from ilfo.cli import main
from ilfo.labelling import LabelConfig
from ilfo.ranges import INT32_MAX, SettingError, declaration
from ilfo.rewards import OOPSConfig
from ilfo.training import TrainConfig, config_from_dict
from tiny_run import DEMOS

GUARDS = {  # small, so that a bad value that slipped through would not start a long run
    "--steps": "200",
    "--start-steps": "100",
    "--horizon": "50",
    "--eval-every": "200",
    "--eval-episodes": "1",
    "--replay-capacity": "1000",
}

FLAG_CASES = [
    (["--td3-lr-actor", "-1"], "td3.lr_actor must be >= 0", "--td3-lr-actor"),
    (["--td3-lr-critic", "nan"], "td3.lr_critic must be >= 0 and finite", "--td3-lr-critic"),
    (["--td3-critic-grad-clip", "-5"], "td3.critic_grad_clip must be positive", "-5.0"),
    (["--td3-exploration-noise", "-0.1"], "td3.exploration_noise must be >= 0", "-0.1"),
    (["--td3-actor-hidden", "0"], "td3.actor_hidden must hold widths >= 1", "(0,)"),
    (["--td3-actor-hidden", "256", "-3"], "td3.actor_hidden must hold widths", "(256, -3)"),
    (
        ["--td3-batch-size", "1000000000"],
        "td3.batch_size must be >= 1 and at most 1,048,576",
        "--td3-batch-size",
    ),
    (["--td3-gamma", "nan"], "td3.gamma must be in (0, 1]", "got nan"),
    (
        ["--replay-capacity", "100000000000"],
        "replay_capacity must be at most 2,147,483,647",
        "--replay-capacity",
    ),
    (["--seed", str(2**63)], "seed must be >= 0 and at most 4,294,967,295", "--seed"),
    (["--seed", str(2**32)], "seed must be >= 0 and at most 4,294,967,295", "4,294,967,296"),
    (["--oops-reg", "inf"], "oops.reg must be positive and finite", "--oops-reg"),
    (["--oops-max-iter", "0"], "oops.max_iter must be an int >= 1", "--oops-max-iter"),
    (["--checkpoint-minutes", "nan"], "checkpoint_minutes must be >= 0 and finite", "0: off"),
    (["--eval-episodes", "0"], "eval_episodes (--eval-episodes) must be from 1 to", "got 0"),
    (["--horizon", "-5"], "horizon must be >= 1", "--horizon"),
    (["--start-steps", "-1"], "start_steps must be >= 0", "--start-steps"),
    (["--algo", "oops-sac", "--sac-tau", "0"], "sac.tau must be in (0, 1]", "--sac-tau"),
    (["--algo", "oops-sac", "--sac-log-std-min", "3"], "log_std_min must be below", "2.0"),
    (["--algo", "oops-td7", "--td7-zs-dim", "0"], "td7.zs_dim must be >= 1", "--td7-zs-dim"),
    (["--algo", "pwil-td3", "--pwil-subsample", "0"], "pwil.subsample must be >= 1", "got 0"),
    (["--algo", "sil", "--trpo-hidden", "0"], "trpo.hidden must hold widths", "--trpo-hidden"),
    (["--algo", "td3", "--demos", DEMOS], "do not apply to algo 'td3'", "the task reward"),
    (["--algo", "sac", "--demos", DEMOS], "do not apply to algo 'sac'", "the task reward"),
    (["--algo", "td7", "--demos", DEMOS], "do not apply to algo 'td7'", "the task reward"),
    (
        ["--algo", "td3", "--env", "CartPole-v1"],
        "CartPole-v1 has a Discrete action space",
        "Box",
    ),
]

FILE_CASES = [
    ({"demos": 123}, "demos must be a string or none, got 123 (int)"),
    ({"env": None}, "env must be a string, got None"),
    ({"env": 5}, "env must be a string, got 5 (int)"),
    ({"td3": {"actor_hidden": "abc"}}, "td3.actor_hidden must be a list of integers"),
    ({"td3": {"critic_hidden": [0, 0]}}, "td3.critic_hidden must hold widths >= 1"),
    ({"td3": {"batch_size": 2.5}}, "td3.batch_size must be an integer, got 2.5"),
    ({"td3": {"lr_critic": "fast"}}, "td3.lr_critic must be a number, got 'fast'"),
    ({"seed": 2**63}, "seed must be >= 0 and at most 4,294,967,295"),
    ({"steps": 1e6}, "steps must be an integer, got 1000000.0"),
    ({"replay_capacity": -5}, "replay_capacity must be >= 1, got -5"),
    ({"oops": {"max_iter": 0}}, "oops.max_iter must be an int >= 1"),
    ({"checkpoint_minutes": "soon"}, "checkpoint_minutes must be a number"),
    ({"healthy_angle_range": ["a", 1]}, "healthy_angle_range must be a list of 2 numbers"),
    ({"fixed_horizon": "yes"}, "fixed_horizon must be true or false or none"),
    ({"algo": "td3", "demos": DEMOS}, "do not apply to algo 'td3': it learns from the task"),
]


def _refused(argv, capsys, out):
    """Run ``ilfo train`` with ``argv``; its error line, checked to be a refusal: exit code 2,
    one line, no traceback, no run directory."""
    assert main(["train", "--no-progress", "--out", str(out), *argv]) == 2
    captured = capsys.readouterr()
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in captured.err, captured.err
    assert not out.exists() or not any(out.iterdir()), "a run directory was left behind"
    assert lines[0].startswith("ilfo: error: ")
    return lines[0]


def _guards(skip=()):
    return [item for flag, value in GUARDS.items() if flag not in skip for item in (flag, value)]


@pytest.mark.parametrize(("flags", "message", "detail"), FLAG_CASES)
def test_a_bad_flag_is_a_one_line_error_naming_it(flags, message, detail, tmp_path, capsys):
    algo = flags[flags.index("--algo") + 1] if "--algo" in flags else "oops-td3"
    demos = ["--demos", DEMOS] if ALGOS[algo].imitation and "--demos" not in flags else []
    guards = _guards({flag for flag in flags if flag.startswith("--")})
    line = _refused([*guards, *demos, *flags], capsys, tmp_path / "runs")
    assert message in line and detail in line, line


@pytest.mark.parametrize(("content", "message"), FILE_CASES)
def test_a_bad_setting_in_a_file_is_a_one_line_error_naming_file_and_setting(
    content, message, tmp_path, capsys
):
    path = tmp_path / "settings.json"
    path.write_text(json.dumps({"demos": DEMOS, **content}))
    skip = {f"--{key.replace('_', '-')}" for key in content}
    line = _refused(["--config", str(path), *_guards(skip)], capsys, tmp_path / "runs")
    assert f"ilfo: error: {path} and the command line: " in line
    assert message in line, line


def test_a_run_past_the_machine_memory_is_refused_with_its_estimate(tmp_path, capsys, monkeypatch):
    from ilfo.training import resources

    monkeypatch.setattr(resources, "machine_memory", lambda: 2**30)  # a 1 GiB machine
    flags = ["--algo", "td3", "--replay-capacity", "20000000", "--env", "Hopper-v5"]
    line = _refused([*_guards({"--replay-capacity"}), *flags], capsys, tmp_path / "runs")
    assert "this run needs ~2.1 GiB of memory and this machine has 1.0 GiB" in line
    assert "replay_capacity 20,000,000 x (2 x 11 + 3 + 2) floats (--replay-capacity)" in line
    # Wide networks and large batches count too.
    wide = ["--td3-critic-hidden", "16384", "16384", "--td3-batch-size", "65536"]
    line = _refused(["--algo", "td3", *_guards(), *wide], capsys, tmp_path / "runs")
    assert "td3.batch_size 65,536 x" in line and "critic_hidden 16384 16384 x 2" in line


def test_the_memory_estimate_of_the_defaults_is_small_and_named_by_setting():
    from ilfo.training.resources import memory_needs, size_text

    needs = memory_needs(TrainConfig(), obs_dim=11, action_dim=3, horizon=1000)
    assert needs[0].what.startswith("replay_capacity 1,000,000 x (2 x 12 + 3 + 2) floats")
    assert needs[0].bytes == 1_000_000 * 29 * 4
    assert sum(n.bytes for n in needs) < 2**30
    on_policy = memory_needs(TrainConfig(algo="sil"), obs_dim=11, action_dim=3, horizon=1000)
    assert on_policy[0].what.startswith("batch_steps 50,000 + the horizon 1,000")
    assert size_text(1536) == "1.5 KiB" and size_text(12 * 2**40) == "12.0 TiB"


def test_an_ot_rewards_matrices_count_in_the_estimate(tmp_path, monkeypatch):
    """OOPS solves an episode of the horizon's atoms against a demo's: float64 matrices of
    horizon x demo atoms (Sinkhorn: the cost, the kernel, Newton's plan and its scaled copy)."""
    from ilfo.training import Trainer, resources

    needs = resources.memory_needs(TrainConfig(), 11, 3, horizon=10**6, demo_lengths=[1000])
    ot = [n for n in needs if n.what.startswith("OOPS's sinkhorn")]
    assert len(ot) == 1 and ot[0].bytes == (4 * 10**9 + 1000**2) * 8
    assert "horizon 1,000,000 x 1,000 demo atoms x 4 matrices" in ot[0].what
    pooled = TrainConfig(num_demos=3, oops={"demo_selection": "pooled"})
    assert "x 3,000 demo atoms" in resources.memory_needs(pooled, 11, 3, 1000, [1000] * 3)[-1].what
    # A task-reward run solves none; an imitation run without an OT reward logs an OT distance.
    assert not any(
        "OT" in n.what for n in resources.memory_needs(TrainConfig(algo="td3"), 11, 3, 1000)
    )
    gaifo = resources.memory_needs(TrainConfig(algo="gaifo-td3"), 11, 3, 1000, [1000])
    assert gaifo[-1].what.startswith("the evaluations' OT distance (Sinkhorn)")
    # A run whose OT would not fit is refused before anything large is allocated.
    monkeypatch.setattr(resources, "machine_memory", lambda: 16 * 2**30)
    config = TrainConfig(horizon=10**6, preset="fast", demos=DEMOS, replay_capacity=1000)
    with pytest.raises(ValueError, match=r"this machine has 16\.0 GiB") as refused:
        Trainer(config, tmp_path / "run", progress=False)
    assert "OOPS's sinkhorn: horizon 1,000,000 x 1,000 demo atoms" in str(refused.value)


def test_an_env_without_a_box_of_actions_is_a_clear_error():
    import gymnasium as gym

    from ilfo.training.build import env_info

    with pytest.raises(ValueError, match=r"CartPole-v1 has a Discrete action space \(Discrete"):
        env_info(gym.make("CartPole-v1"), "CartPole-v1")


def test_errors_name_the_part_and_flag_and_survive_pickling():
    with pytest.raises(SettingError, match=r"^batch_size must be >= 1 and at most") as caught:
        TD3Config(batch_size=0)
    assert caught.value.setting == "batch_size"
    with pytest.raises(ValueError, match=r"^td3\.batch_size .*got 0 \(--td3-batch-size\)$"):
        TrainConfig(td3={"batch_size": 0})
    # A field the trainer sets has no flag to name.
    with pytest.raises(ValueError, match=r"^td3\.max_time must be >= 1, got 0$"):
        TrainConfig(td3={"max_time": 0})
    again = pickle.loads(pickle.dumps(caught.value))
    assert str(again) == str(caught.value) and again.setting == "batch_size"


def test_accepted_values_are_held_as_their_declared_types():
    import numpy as np

    config = TD3Config(actor_hidden=[np.int64(64)], tau=1, batch_size=np.int32(32))
    assert config.actor_hidden == (64,) and type(config.actor_hidden[0]) is int
    assert type(config.tau) is float and type(config.batch_size) is int
    assert TD3Config(critic_grad_clip=None).critic_grad_clip is None
    assert TrainConfig(healthy_angle_range=[-0.1, 0.1]).healthy_angle_range == (-0.1, 0.1)


def test_more_updates_than_the_agents_int32_counter_holds_are_refused_up_front():
    """A run's updates, steps * updates_per_step at most, are counted in the agents' int32
    ``state.step``: one more than it holds would wrap to negative mid-run."""
    from ilfo.agents import make_td3

    step = make_td3(TD3Config.fast(), 3, 1).init(0).step
    assert jnp.iinfo(step.dtype).max == INT32_MAX
    assert int(step + INT32_MAX + 1) < 0  # why: the count wraps, silently
    TrainConfig(steps=2**16, updates_per_step=2**15 - 1)  # 2**31 - 2**16 updates: accepted
    with pytest.raises(ValueError, match="steps \\* updates_per_step must be at most"):
        TrainConfig(steps=2**16, updates_per_step=2**15)
    # (Not through `ilfo train`: without the check, that test would train for days.)
    with pytest.raises(ValueError, match="= 2,147,483,648 \\(--steps, --updates-per-step\\)"):
        config_from_dict({"steps": 2**30, "updates_per_step": 2}, "config.json")


RESULTS = Path(__file__).parents[1] / "docs" / "results"
KEPT_CONFIGS = sorted(RESULTS.glob("runs/*/config.json")) + sorted(
    RESULTS.glob("controls/*/config.json")
)


@pytest.mark.parametrize(
    "path", KEPT_CONFIGS, ids=lambda p: f"{p.parent.parent.name}/{p.parent.name}"
)
def test_a_kept_runs_config_json_is_the_config_of_a_new_run(path):
    """``ilfo train --config RUN/config.json``'s config (built as the flag builds it, not
    trained): the run's settings as its record reads back, with the flags' changes."""
    from ilfo.cli.train import config_from_args
    from ilfo.training import read_settings

    config = config_from_args(str(path), {"steps": 2000, "out": "x"}, {})
    got = json.loads(json.dumps(dataclasses.asdict(config)))
    for key, value in {**read_settings(path), "steps": 2000, "out": "x"}.items():
        if isinstance(value, dict):  # a part: the fields it recorded (newer ones: defaults)
            assert {k: got[key][k] for k in value} == value, key
        else:
            assert got[key] == value, key


def test_a_task_reward_runs_config_json_with_demos_is_a_config_without_them(tmp_path, capsys):
    """Records from before demos were refused for the task reward list them: as ``--config``
    they read back without them, while ``--demos``, or a settings file that is not a run's
    record, with a task-reward algo is refused."""
    from ilfo.cli.train import config_from_args

    assert len(KEPT_CONFIGS) >= 20  # the runs and controls the test above reads
    run = tmp_path / "old-td3-run"
    run.mkdir()
    (run / "metrics.csv").write_text("step,episode\n1000,1\n")  # a run's record
    record = json.dumps({**dataclasses.asdict(TrainConfig(algo="td3")), "demos": DEMOS})
    (run / "config.json").write_text(record)
    assert config_from_args(str(run / "config.json"), {"steps": 2000}, {}).demos is None
    flags = ["--config", str(run / "config.json"), "--demos", DEMOS, *_guards()]
    assert "demos (--demos) do not apply to algo 'td3'" in _refused(flags, capsys, tmp_path / "r")
    (tmp_path / "settings.json").write_text(record)
    with pytest.raises(ValueError, match="do not apply to algo 'td3'"):
        config_from_args(str(tmp_path / "settings.json"), {}, {})


WILD = st.one_of(
    st.integers(min_value=-(2**70), max_value=2**70),
    st.sampled_from([0, 1, -1, 2, 1000, INT32_MAX, INT32_MAX + 1, 2**32, 2**63, 10**30]),
    st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from([0.0, -0.0, 0.5, 1.0, 1.5, 2.5, 1e-300, 1e300, math.nan, math.inf]),
    st.booleans(),
    st.text(max_size=4),
    st.none(),
    st.lists(st.integers(min_value=-3, max_value=70_000), max_size=3),
    st.lists(st.floats(allow_nan=True), max_size=2),
)


def _numeric_fields(cls):
    """The fields of ``cls`` that hold numbers: ints, floats (optional or not), tuples."""
    hints = typing.get_type_hints(cls)
    return [
        f.name
        for f in dataclasses.fields(cls)
        if {int, float} & {hints[f.name], *typing.get_args(hints[f.name])}
        or typing.get_origin(_bare(hints[f.name])) is tuple
    ]


def _bare(hint):
    args = [a for a in typing.get_args(hint) if a is not type(None)]
    return args[0] if typing.get_origin(hint) is not tuple and len(args) == 1 else hint


def _in_declared_range(cls, name, value):
    """Whether an accepted ``value`` of field ``name`` is what its declaration allows,
    checked here from the declaration's bounds (not with ``ilfo.ranges``' own test)."""
    if value is None:
        return type(None) in typing.get_args(typing.get_type_hints(cls)[name])
    declared = declaration(cls, name)
    items = value if isinstance(value, tuple) else (value,)
    if declared is not None and len(items) < declared.min_items:
        return False
    return all(_item_in_range(item, declared) for item in items)


def _item_in_range(item, declared):
    if type(item) not in (int, float):
        return False
    if type(item) is float and not (math.isfinite(item) or (declared and declared.inf)):
        return False
    low = None if declared is None else declared.low
    high = None if declared is None else declared.high
    if high is None and type(item) is int:
        high = INT32_MAX
    if low is not None and (item < low or (declared.low_open and item == low)):
        return False
    return high is None or not (item > high or (declared and declared.high_open and item == high))


@pytest.mark.parametrize(
    "cls", [TD3Config, TD7Config, SACConfig, OOPSConfig, TrainConfig, LabelConfig]
)
def test_any_value_of_a_numeric_field_is_held_in_range_or_refused_with_a_value_error(cls):
    names = _numeric_fields(cls)
    assert len(names) >= 4

    @settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
    @given(st.dictionaries(st.sampled_from(names), WILD, max_size=3))
    def check(values):
        try:
            config = cls(**values)
        except ValueError:
            return  # a refusal, as it should be (a TypeError or OverflowError fails the test)
        for name in values:
            assert _in_declared_range(cls, name, getattr(config, name)), (name, values)

    check()
