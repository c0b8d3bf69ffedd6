"""What a sweep backend and its worker processes (``ilfo.experiments.worker``) agree on.

Apart from the worker so that a backend never imports the module that ``python -m`` runs as
``__main__`` (runpy warns when the package's import already loaded it).
"""

PARENT_SIGNAL_ENV = "ILFO_PARENT_DEATH_SIGNAL"
"""Set by the local backend: the worker gets SIGINT when its sweep process dies (Linux), so
a killed sweep leaves no orphan runs behind, each checkpointed where it stood."""
EXIT_BUSY = 75
"""A worker's exit when another process holds its run's lock (BSD's EX_TEMPFAIL)."""
