"""The estimate of a run's cost reads its rates from the data that bench/rates.py writes."""

import pytest

from ilfo.algos import ALGOS
from ilfo.experiments.estimates import (
    RUN_FIXED_CORE_SECONDS,
    measured_rates,
    run_core_seconds,
    steps_per_core_second,
)


def test_every_measured_rate_is_an_algos_and_positive():
    rates = measured_rates()
    assert "oops-td3" in rates
    for algo, row in rates.items():
        assert algo in ALGOS
        assert row["runs"] >= 1 and row["steps_per_s"] > 0
        assert all(rate > 0 for rate in row["envs"].values())


def test_an_env_with_kept_runs_is_costed_at_its_own_rate():
    envs = measured_rates()["oops-td3"]["envs"]
    slowest, fastest = min(envs, key=envs.get), max(envs, key=envs.get)
    assert envs[slowest] < envs[fastest]

    def seconds(env):
        config = {"algo": "oops-td3", "env": env, "preset": "fast"}
        return run_core_seconds(config, 100_000) - RUN_FIXED_CORE_SECONDS

    assert seconds(slowest) == pytest.approx(100_000 / envs[slowest])
    assert seconds(fastest) == pytest.approx(100_000 / envs[fastest])
    # An env without kept runs of the algo: the algo's median over its runs.
    median = measured_rates()["oops-td3"]["steps_per_s"]
    assert steps_per_core_second("oops-td3", "NoSuchEnv-v0") == median
    assert steps_per_core_second("oops-td3") == median


def test_an_algo_without_kept_runs_has_no_estimate_unless_given_a_rate():
    unmeasured = next(algo for algo in ALGOS if algo not in measured_rates())
    config = {"algo": unmeasured, "preset": "fast"}
    assert run_core_seconds(config, 1000) is None
    assert run_core_seconds(config, 1000, unmeasured_rate=100.0) == pytest.approx(
        RUN_FIXED_CORE_SECONDS + 10.0
    )
