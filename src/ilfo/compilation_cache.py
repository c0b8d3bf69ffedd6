"""JAX's persistent compilation cache, as the ``ilfo`` command uses it.

Every ``ilfo train`` start or ``--resume`` compiles the agent's update chunks anew, tens of
seconds on a 2-core CPU. JAX can keep compiled programs on disk and
load them in a later process when the program, the compile options, jax/jaxlib and the machine
are the same; a program that does not match is compiled as usual, so the cache changes how long
a start takes, never what runs.

The ``ilfo`` command enables it (``enable_compilation_cache``); the library, imported into a
user's own code, leaves JAX's configuration alone. Where it goes, in order:

1. ``ILFO_COMPILATION_CACHE=off`` (or ``0``, ``none``, ``false``, ``no``): ilfo sets no cache.
2. ``ILFO_COMPILATION_CACHE=DIR``: that directory.
3. JAX's own setting, if the user made one (``JAX_COMPILATION_CACHE_DIR``): left as it is.
4. Otherwise ``$XDG_CACHE_HOME/ilfo/jax`` (``~/.cache/ilfo/jax``).

The cache holds programs that took at least ``MIN_COMPILE_SECONDS`` to compile and is trimmed,
least recently used first, to ``MAX_BYTES`` (JAX's own settings win where the user made them:
``JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS``, ``JAX_COMPILATION_CACHE_MAX_SIZE``).
"""

from __future__ import annotations

import importlib.util
import os
import warnings
from collections.abc import Mapping
from pathlib import Path

import jax

__all__ = [
    "ENV_VAR",
    "MAX_BYTES",
    "MIN_COMPILE_SECONDS",
    "cache_dir_from_env",
    "enable_compilation_cache",
]

ENV_VAR = "ILFO_COMPILATION_CACHE"
MIN_COMPILE_SECONDS = 0.5
"""Programs that compile faster than this are not worth a file (JAX's default is 1 s; the
smaller update chunks take 0.5-1 s)."""
MAX_BYTES = 2 * 1024**3
"""Size the cache is trimmed to (an update chunk takes ~0.4 MB, a training setting ~2.5 MB)."""

_OFF = ("off", "0", "none", "false", "no")


def cache_dir_from_env(environ: Mapping[str, str] | None = None) -> Path | None:
    """The cache directory ``environ`` (default ``os.environ``) asks for; None = no cache.

    Raises ValueError for an empty ``ILFO_COMPILATION_CACHE``, which names neither a directory
    nor ``off``. Does not look at JAX's own setting (``enable_compilation_cache`` does)."""
    env = os.environ if environ is None else environ
    value = env.get(ENV_VAR)
    if value is not None:
        value = value.strip()
        if not value:
            raise ValueError(f"{ENV_VAR} is empty: give a directory, or 'off' for no cache")
        return None if value.lower() in _OFF else Path(value).expanduser()
    base = env.get("XDG_CACHE_HOME") or str(Path(env.get("HOME", "~")) / ".cache")
    return Path(base).expanduser() / "ilfo" / "jax"


def enable_compilation_cache(environ: Mapping[str, str] | None = None) -> Path | None:
    """Point JAX's persistent compilation cache where ``cache_dir_from_env`` says, unless the
    user configured JAX's cache directory themselves and ``ILFO_COMPILATION_CACHE`` is unset
    (then theirs is kept). With ``ILFO_COMPILATION_CACHE=off`` JAX's configuration is left
    alone. A directory that cannot be written turns the cache off with one warning. Returns the
    directory in use, or None when there is none. Call it before the first jitted call of the
    process: JAX fixes its cache on the first compilation."""
    env = os.environ if environ is None else environ
    directory = cache_dir_from_env(env)
    # JAX_COMPILATION_CACHE_DIR, if the user set it (JAX defines its options at run time, so
    # the type checker cannot see them as attributes).
    own = jax.config.jax_compilation_cache_dir  # type: ignore[attr-defined]
    if directory is None or (own and ENV_VAR not in env):
        return Path(own) if own else None
    try:
        directory.mkdir(parents=True, exist_ok=True)
        writable = os.access(directory, os.W_OK)
    except OSError:
        writable = False
    if not writable:  # else JAX would warn at every compilation of the run
        warnings.warn(
            f"compilation cache off: cannot write {directory} (set {ENV_VAR}=DIR or off)",
            stacklevel=2,
        )
        return None
    jax.config.update("jax_compilation_cache_dir", str(directory))
    if "JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS" not in env:
        jax.config.update("jax_persistent_cache_min_compile_time_secs", MIN_COMPILE_SECONDS)
    # JAX bounds the cache only with filelock (a dependency of ilfo); unbounded rather than
    # failing at the first compilation where it is missing.
    if "JAX_COMPILATION_CACHE_MAX_SIZE" not in env and importlib.util.find_spec("filelock"):
        jax.config.update("jax_compilation_cache_max_size", MAX_BYTES)
    return directory
