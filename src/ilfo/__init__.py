"""ilfo: imitation learning from observation (OOPS and its peers)."""

__version__ = "0.1.0"
