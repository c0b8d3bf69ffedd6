"""Where the `ilfo` command keeps JAX's persistent compilation cache."""

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from ilfo.cli import main
from ilfo.compilation_cache import ENV_VAR, cache_dir_from_env, enable_compilation_cache


@pytest.mark.parametrize("value", ["off", "OFF", "0", "none", "false", "no", " off "])
def test_off_values_disable_it(value):
    assert cache_dir_from_env({ENV_VAR: value, "HOME": "/home/u"}) is None


def test_a_directory_is_used_as_given():
    assert cache_dir_from_env({ENV_VAR: "/data/c"}) == Path("/data/c")
    assert cache_dir_from_env({ENV_VAR: "~/c", "HOME": "/home/u"}) == Path.home() / "c"


def test_default_follows_xdg_cache_home_then_home():
    assert cache_dir_from_env({"XDG_CACHE_HOME": "/x", "HOME": "/h"}) == Path("/x/ilfo/jax")
    assert cache_dir_from_env({"HOME": "/h"}) == Path("/h/.cache/ilfo/jax")


def test_empty_value_is_an_error_the_cli_reports(monkeypatch, capsys):
    with pytest.raises(ValueError, match="empty"):
        cache_dir_from_env({ENV_VAR: " "})
    monkeypatch.setenv(ENV_VAR, "")
    assert main(["plot", "no-such-run"]) == 2
    assert f"{ENV_VAR} is empty" in capsys.readouterr().err


_PROBE = """
import json, sys
import jax, jax.numpy as jnp
from ilfo.compilation_cache import enable_compilation_cache
used = enable_compilation_cache()
jax.jit(lambda x: jnp.sin(x) @ x.T)(jnp.ones((8, 8))).block_until_ready()
print(json.dumps({"used": None if used is None else str(used),
                  "jax": jax.config.jax_compilation_cache_dir}))
"""


def _probe(tmp_path: Path, **env: str) -> dict:
    base = {k: v for k, v in os.environ.items() if not k.startswith(("JAX_", "ILFO_"))}
    base.update(XDG_CACHE_HOME=str(tmp_path / "xdg"), JAX_PLATFORMS="cpu")
    # Cache even this tiny program (the user's own JAX setting, which ilfo respects).
    base.update(JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS="0", **env)
    out = subprocess.run(
        [sys.executable, "-c", _PROBE], env=base, capture_output=True, text=True, check=True
    )
    return json.loads(out.stdout.strip().splitlines()[-1])


@pytest.mark.integration
def test_enabled_cache_receives_compiled_programs(tmp_path):
    cache = tmp_path / "cache"
    assert _probe(tmp_path, **{ENV_VAR: str(cache)}) == {"used": str(cache), "jax": str(cache)}
    assert any(cache.iterdir())
    default = tmp_path / "xdg" / "ilfo" / "jax"
    assert _probe(tmp_path)["used"] == str(default)
    assert any(default.iterdir())


@pytest.mark.integration
def test_users_own_jax_setting_wins_unless_ilfo_is_told(tmp_path):
    own = str(tmp_path / "own")
    assert _probe(tmp_path, JAX_COMPILATION_CACHE_DIR=own) == {"used": own, "jax": own}
    assert _probe(tmp_path, JAX_COMPILATION_CACHE_DIR=own, **{ENV_VAR: "off"})["used"] == own
    assert _probe(tmp_path, **{ENV_VAR: "off"}) == {"used": None, "jax": None}
    assert not (tmp_path / "xdg").exists()


def test_a_directory_that_cannot_be_written_turns_it_off_with_one_warning(tmp_path):
    not_a_dir = tmp_path / "file"
    not_a_dir.write_text("")
    with pytest.warns(UserWarning, match="compilation cache off: cannot write"):
        assert enable_compilation_cache({ENV_VAR: str(not_a_dir / "cache")}) is None
