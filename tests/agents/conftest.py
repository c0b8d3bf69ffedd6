"""Fixtures shared by the agent tests."""

import pytest
from agent_helpers import random_buffer

from ilfo.replay import ReplayBuffer


@pytest.fixture
def buffer() -> ReplayBuffer:
    """A small buffer of random episodes (``agent_helpers.random_buffer``), fresh for each test."""
    return random_buffer()
