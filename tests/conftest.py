"""Test-session setup."""

import os

import jax
import pytest

# The `ilfo` command enables a persistent compilation cache under ~/.cache; tests run it in
# process and in subprocesses, and must not write there (the session cache below serves).
os.environ["ILFO_COMPILATION_CACHE"] = "off"


@pytest.fixture(scope="session", autouse=True)
def _compilation_cache(tmp_path_factory):
    # Agents jit closures over their config, so every Trainer compiles its updates anew; a
    # compilation cache shared by the session lets identical programs compile once.
    jax.config.update("jax_compilation_cache_dir", str(tmp_path_factory.mktemp("jax_cache")))
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0)
    jax.config.update("jax_persistent_cache_min_entry_size_bytes", -1)


@pytest.fixture(scope="session", autouse=True)
def _sb3_logs(tmp_path_factory):
    # Stable-Baselines3 makes a log directory in /tmp at each learn() unless told where; the
    # tests' go with pytest's temporary files (subprocesses, such as the example, inherit it).
    os.environ["SB3_LOGDIR"] = str(tmp_path_factory.mktemp("sb3_logs"))


def pytest_addoption(parser):
    parser.addoption(
        "--update-golden",
        action="store_true",
        help="rewrite tests/golden/ from the current code (tests/agents/test_golden.py)",
    )
