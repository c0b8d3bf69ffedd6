"""Configs as flags and as JSON: ``ilfo.config`` and the agent / rewarder configs of a run."""

import argparse
import dataclasses
import json

import pytest

from ilfo.agents import SACConfig, TD3Config, ddpg_config
from ilfo.cli import main
from ilfo.config import add_dataclass_arguments, none_or, overrides_from_args
from ilfo.rewards import OOPSConfig, PWILConfig
from ilfo.training import TrainConfig


def test_help_lists_every_agent_and_rewarder_flag_with_its_doc(capsys):
    with pytest.raises(SystemExit):
        main(["train", "--help"])
    out = " ".join(capsys.readouterr().out.split())  # argparse wraps lines
    for flag, doc in [
        ("--td3-batch-size", "Transitions per gradient step. (default: 100)"),
        ("--td3-critic-hidden", "(default: paper 1024 1024, fast 256 256)"),
        ("--td3-critic-grad-clip", '("none" for None) (default: 25.0)'),
        ("--no-td3-time-augmentation", "Observations end with a time feature"),
        ("--sac-tau", "Polyak rate of the target critics"),
        ("--sac-target-entropy", "None = -action_dim."),
        ("--oops-reg", "Sinkhorn's absolute entropic regularisation lambda. (default: 0.05)"),
        ("--oops-demo-selection", "With several demos"),
        ("--pwil-alpha", "Reward amplitude alpha. (default: 5.0)"),
        ("--trpo-max-kl", "(default: 0.1)"),
        ("--sil-expert-subsample", "(default: 20)"),
        ("--oops-adv-critic-every", "(default: 1)"),
        ("--td7-critic-hidden", "(default: paper 256, fast 128)"),
        ("--td7-target-update-every", "(default: 250)"),
    ]:
        assert flag in out and doc in out, flag
    assert (
        "TD3/DDPG agent (oops-td3, oops-ddpg, pwil-td3, oops-adv-td3, gaifo-td3, td3; overrides "
        "the --preset)" in out
    )
    assert "OOPS rewarder (oops-td3, oops-ddpg, oops-sac, oops-td7)" in out
    assert "TD7 agent (oops-td7, td7; overrides the --preset)" in out
    assert "SAC agent (oops-sac, firl-fkl, sac):" in out  # one config for both presets
    # Set by the trainer, so not flags.
    assert "--td3-max-time" not in out and "--oops-seed" not in out
    assert "--sil-seed" not in out and "--oops-adv-seed" not in out


def test_prefixed_flags_do_not_collide_and_none_is_a_value():
    parser = argparse.ArgumentParser()
    add_dataclass_arguments(parser, TD3Config, prefix="td3")
    add_dataclass_arguments(parser, SACConfig, prefix="sac")
    td3 = ["--td3-batch-size", "32", "--td3-critic-grad-clip", "none"]
    td3 += ["--td3-critic-hidden", "64", "64"]
    sac = ["--sac-batch-size", "64", "--no-sac-autotune", "--sac-target-entropy", "-2"]
    args = parser.parse_args(td3 + sac)
    assert overrides_from_args(args, TD3Config, prefix="td3") == {
        "batch_size": 32,
        "critic_grad_clip": None,
        "critic_hidden": (64, 64),
    }
    assert overrides_from_args(args, SACConfig, prefix="sac") == {
        "batch_size": 64,
        "autotune": False,
        "target_entropy": -2.0,
    }
    assert overrides_from_args(parser.parse_args([]), TD3Config, prefix="td3") == {}


def test_none_or():
    parse = none_or(float)
    assert parse("none") is None and parse("None") is None and parse(" NONE ") is None
    assert parse("2.5") == 2.5
    with pytest.raises(ValueError):
        parse("nothing")
    parser = argparse.ArgumentParser()
    add_dataclass_arguments(parser, TD3Config, prefix="td3")
    with pytest.raises(SystemExit):
        parser.parse_args(["--td3-critic-grad-clip", "off"])


def _round_trip(config: TrainConfig) -> TrainConfig:
    return TrainConfig(**json.loads(json.dumps(dataclasses.asdict(config))))


@pytest.mark.parametrize(
    "config",
    [
        TrainConfig(),
        TrainConfig(
            td3=TD3Config.fast(critic_hidden=(64, 32), critic_grad_clip=None, batch_size=32),
            oops=OOPSConfig(reg=0.1, solver="emd", seed=3),
            seed=3,
        ),
        TrainConfig(algo="oops-sac", sac=SACConfig(target_entropy=-1.5, actor_hidden=(8,))),
        TrainConfig(algo="pwil-td3", pwil=PWILConfig(alpha=2.0, horizon=500)),
        TrainConfig(algo="oops-ddpg", horizon=100).resolved(100),
        TrainConfig(algo="sac", fixed_horizon=True).resolved(1000),
        TrainConfig(algo="sac", healthy_angle_range=(-0.1, 0.1)),
    ],
)
def test_train_config_survives_a_json_round_trip(config):
    again = _round_trip(config)
    assert again == config
    for name in ("td3", "sac", "oops", "pwil"):
        assert type(getattr(again, name)) is type(getattr(config, name))
    if config.td3 is not None:
        assert isinstance(again.td3.critic_hidden, tuple)


def test_float_pair_flag_and_its_validation():
    parser = argparse.ArgumentParser()
    add_dataclass_arguments(parser, TrainConfig)
    args = parser.parse_args(["--healthy-angle-range", "-0.1", "0.15"])
    assert overrides_from_args(args, TrainConfig) == {"healthy_angle_range": (-0.1, 0.15)}
    with pytest.raises(SystemExit):  # two numbers, not one
        parser.parse_args(["--healthy-angle-range", "0.1"])
    for bad in ((0.1, -0.1), (0.0, 0.0), (0.1,)):
        with pytest.raises(ValueError, match="healthy_angle_range"):
            TrainConfig(healthy_angle_range=bad)


def test_resolved_config_builds_the_same_agent_and_rewarder():
    for algo in ("oops-td3", "oops-ddpg", "oops-sac", "pwil-td3", "td3", "sac"):
        for preset in ("paper", "fast"):
            config = TrainConfig(algo=algo, preset=preset, seed=2)
            resolved = _round_trip(config.resolved(100))
            assert resolved.agent_config(100) == config.agent_config(100)
            assert resolved.part_config("oops") == config.part_config("oops")
            assert resolved.part_config("pwil") == config.part_config("pwil")
            assert resolved.resolved(100) == resolved  # idempotent
            # The episodes as resolved now: a later change of the algo's default (f-IRL's
            # was) cannot change how a resumed run's episodes end.
            assert resolved.fixed_horizon == config.uses_fixed_horizon
    assert TrainConfig(algo="firl-fkl").resolved(100).fixed_horizon is False


def test_pwil_trains_on_standard_episodes():
    """(Its older runs, recorded with the episodes unresolved, read as the fixed horizon they
    ran: test_compat.)"""
    pwil = TrainConfig(algo="pwil-td3")
    assert not pwil.uses_fixed_horizon and pwil.resolved(1000).fixed_horizon is False
    assert not pwil.agent_config(1000).time_augmentation  # no time feature without a horizon
    assert TrainConfig(algo="pwil-td3", fixed_horizon=True).uses_fixed_horizon  # as asked


def test_default_agent_and_rewarder_configs_are_the_presets():
    # Fixed-horizon imitation: the preset with time augmentation on, max_time the horizon.
    paper = TrainConfig().agent_config(1000)
    assert paper == dataclasses.replace(TD3Config.paper(), max_time=1000)
    fast = TrainConfig(preset="fast").agent_config(100)
    assert fast == dataclasses.replace(TD3Config.fast(), max_time=100)
    assert TrainConfig(algo="oops-ddpg").agent_config(1000) == ddpg_config(TD3Config.paper())
    # Standard mode (task reward): no time feature, so no time augmentation.
    assert not TrainConfig(algo="td3").agent_config(1000).time_augmentation
    assert TrainConfig(algo="td3", fixed_horizon=True).agent_config(1000).time_augmentation
    assert TrainConfig(algo="sac").agent_config(1000) == SACConfig()
    assert TrainConfig(seed=4).part_config("oops") == OOPSConfig(seed=4)
    # An explicit OOPS config keeps its settings, but the run's seed seeds it.
    assert TrainConfig(seed=4, oops=OOPSConfig(reg=0.2)).part_config("oops").seed == 4
    # Explicit time augmentation off stays off; the trainer sets max_time.
    custom = TrainConfig(td3=TD3Config(time_augmentation=False, max_time=7)).agent_config(50)
    assert not custom.time_augmentation and custom.max_time == 50


def test_mismatched_or_malformed_sub_configs_are_clear_errors():
    with pytest.raises(ValueError, match=r"sac settings .* do not apply to algo 'oops-td3'"):
        TrainConfig(sac=SACConfig())
    with pytest.raises(ValueError, match=r"td3 settings .* algo 'sac'.*oops-td3, oops-ddpg"):
        TrainConfig(algo="sac", td3={})
    with pytest.raises(ValueError, match=r"oops settings .* algo 'pwil-td3'"):
        TrainConfig(algo="pwil-td3", oops=OOPSConfig())
    with pytest.raises(ValueError, match=r"pwil settings .* algo 'td3'.*no rewarder"):
        TrainConfig(algo="td3", pwil=PWILConfig())
    with pytest.raises(ValueError, match="TD3Config has no field"):
        TrainConfig(td3={"batch": 3})
    with pytest.raises(TypeError, match="td3 must be a TD3Config"):
        TrainConfig(td3=3)
    # A value of the wrong type (a hand-edited file) names the field and the type it needs.
    with pytest.raises(ValueError, match=r"td3.batch_size must be int, got 'big' \(str\)"):
        TrainConfig(td3={"batch_size": "big"})
    with pytest.raises(ValueError, match=r"td3.critic_hidden must be tuple\[int, ...\]"):
        TrainConfig(td3={"critic_hidden": [256, "x"]})
    with pytest.raises(ValueError, match=r"oops.reg must be float, got True"):
        TrainConfig(oops={"reg": True})
    with pytest.raises(ValueError, match=r"oops.metric must be Literal"):
        TrainConfig(oops={"metric": "manhattan"})
    tolerant = TrainConfig(td3={"tau": 1, "critic_hidden": [64, 64], "critic_grad_clip": None})
    assert tolerant.td3.tau == 1 and tolerant.td3.critic_hidden == (64, 64)
    with pytest.raises(ValueError, match=r"oops.max_iter must be int, got None"):
        TrainConfig(oops={"max_iter": None})


def test_the_algo_names_are_the_registry():
    from typing import get_args

    from ilfo.algos import ALGOS, PART_CONFIGS, algos_using
    from ilfo.training import Algo

    assert list(get_args(Algo)) == list(ALGOS)
    for name, recipe in ALGOS.items():
        config = TrainConfig(algo=name)
        # An algo with a reward part imitates demos; one without refuses them, not ignores them.
        if recipe.reward is None:
            with pytest.raises(ValueError, match="learns from the task reward"):
                TrainConfig(algo=name, demos="demos.npz")
        else:
            assert TrainConfig(algo=name, demos="demos.npz").demos == "demos.npz"
        resolved = config.resolved(100)
        used = {recipe.agent, recipe.reward} - {None}
        assert {part for part in PART_CONFIGS if getattr(resolved, part) is not None} == used
    assert algos_using("pwil") == ["pwil-td3"]
    with pytest.raises(ValueError, match="unknown algo 'gail'; choose one of oops-td3"):
        TrainConfig(algo="gail")


def test_config_from_settings_file_and_flags(tmp_path):
    """`ilfo train --config FILE`: a hand-written subset (a part's dict changes single fields of
    its default), flags over it, and a run's own resolved config.json read back unchanged."""
    from ilfo.cli.train import config_from_args
    from ilfo.training import TrainConfig, config_from_settings

    path = tmp_path / "subset.json"
    path.write_text(json.dumps({"env": "Walker2d-v5", "preset": "fast", "td3": {"tau": 0.01}}))
    config = config_from_args(str(path), {"seed": 4}, {"td3": {"batch_size": 64}})
    fast = TrainConfig(preset="fast").part_config("td3")
    assert config.env == "Walker2d-v5" and config.seed == 4
    assert config.td3 == dataclasses.replace(fast, tau=0.01, batch_size=64)
    resolved = config.resolved(horizon=1000)
    record = json.loads(json.dumps(dataclasses.asdict(resolved)))
    assert config_from_settings(record, "config.json") == resolved
    toml = tmp_path / "subset.toml"
    toml.write_text('algo = "pwil-td3"\n[pwil]\nbeta = 2.0\n')
    assert config_from_args(str(toml), {}, {}).pwil.beta == 2.0
    bad = tmp_path / "bad.json"
    bad.write_text('{"oops": {"nope": 1}}')
    with pytest.raises(ValueError, match="oops has no setting"):
        config_from_args(str(bad), {}, {})
    bad.write_text("[1, 2]")
    with pytest.raises(ValueError, match="must hold an object"):
        config_from_args(str(bad), {}, {})
    with pytest.raises(FileNotFoundError):
        config_from_args(str(tmp_path / "missing.json"), {}, {})
    (tmp_path / "run").mkdir()
    (tmp_path / "run" / "config.json").write_text("{}")
    with pytest.raises(ValueError, match=r"is a directory, not a settings file: pass .*config"):
        config_from_args(str(tmp_path / "run"), {}, {})


def test_a_run_configs_resolved_settings_follow_its_env_and_algo_under_other_flags(tmp_path):
    """config.json records what its env and algo observed; --config FILE with another env or
    algo takes the new pair's default, unless a flag (or a hand-written file) says."""
    from ilfo.cli.train import config_from_args, settings_from_args
    from ilfo.training import TrainConfig

    record = tmp_path / "config.json"
    humanoid = TrainConfig(env="Humanoid-v5").resolved(horizon=1000)
    # Without its OOPS part, which would not apply to the task-reward algo below.
    record.write_text(json.dumps(dataclasses.asdict(dataclasses.replace(humanoid, oops=None))))
    assert humanoid.contact_forces is False
    assert TrainConfig().resolved(horizon=1000).contact_forces is None  # Hopper: nothing to drop
    assert config_from_args(str(record), {"seed": 3}, {}).contact_forces is False
    assert config_from_args(str(record), {"algo": "td3"}, {}).observes_contact_forces
    control = config_from_args(str(record), {"algo": "td3", "contact_forces": False}, {})
    assert not control.observes_contact_forces
    hopper = config_from_args(str(record), {"env": "Hopper-v5"}, {})  # no error: the default
    assert hopper.env == "Hopper-v5" and hopper.contact_forces is None
    # A sweep's axes replace the file's env and algo: its choice goes with them.
    assert "contact_forces" not in settings_from_args(str(record), {}, {}, ("env", "algo"))
    subset = tmp_path / "subset.json"
    subset.write_text(json.dumps({"contact_forces": True}))
    assert config_from_args(str(subset), {"env": "Ant-v5"}, {}).observes_contact_forces
    # Episodes and random steps are recorded resolved too: another algo takes its own.
    oops = tmp_path / "oops.json"
    resolved = TrainConfig(preset="fast").resolved(1000)  # without parts other algos refuse
    oops.write_text(json.dumps(dataclasses.asdict(dataclasses.replace(resolved, td3=None))))
    assert resolved.fixed_horizon is True and resolved.start_steps == 10_000
    settings = json.loads(oops.read_text())
    oops.write_text(json.dumps({**settings, "oops": None}))
    firl = config_from_args(str(oops), {"algo": "firl-fkl"}, {})
    assert not firl.uses_fixed_horizon and firl.random_steps == 1000  # f-IRL's authors'
    assert config_from_args(str(oops), {"seed": 1}, {}).fixed_horizon is True  # a repeat keeps
    kept = config_from_args(str(oops), {"algo": "sil", "fixed_horizon": True}, {})
    assert kept.uses_fixed_horizon  # unless a flag says
