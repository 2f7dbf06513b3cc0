"""Fixtures for the robots app: the simulated demo world and fake endpoints."""

import pytest

from simworker.testing import running_world
from tests.robots.fakes import GraphEndpoint


@pytest.fixture(scope="module")
def paper_world():
    """The paper's demo world (robots, turtlebot, husky, tiago, spot, tb3_nav2 endpoints), one per module."""
    with running_world("paper") as sim:
        yield sim


@pytest.fixture
def endpoint():
    """Start GraphEndpoint(s) built by a function of the graph; all are closed after the test."""
    started = []

    def make(**kwargs) -> GraphEndpoint:
        ep = GraphEndpoint(**kwargs).start()
        started.append(ep)
        return ep

    yield make
    for ep in started:
        ep.close()
