"""The action registry: everything about one action a person can ask for, in one entry (no Django).

An entry holds the ontology term (category, destination rules, synonyms: the interpreter seeds its ontology
from it), the binding roles a robot needs to do it (fleetcore/bindings.py), the state the robot is in while it
runs (its priority follows: work > motion > dialog), the executor's handler (a dotted path, imported by the
executor only), and how a stop cancels it. Adding an action is adding an entry here and its handler.
"""

from __future__ import annotations

from dataclasses import dataclass

from fleetcore.states import PRIORITY, State


class Stop:
    """How a stop cancels a running action."""

    HALT = "halt"  # publish a zero velocity
    CANCEL = (
        "cancel"  # cancel the goal the robot's own stack runs (navigation, docking), then a zero velocity
    )
    NONE = "none"  # nothing moves


@dataclass(frozen=True)
class Action:
    name: str
    category: str  # ontology category: motion | task | control | query
    state: State  # the robot's state while the action runs
    handler: str | None  # dotted path of the executor handler; None: not run by the executor
    needs: tuple[tuple[str, ...], ...] = ()  # binding roles: every group needed, any role of a group will do
    stop: str = Stop.HALT
    takes_destination: bool = False
    requires_destination: bool = False
    countable: bool = False
    accepts: tuple[str, ...] = ()  # destination classes (owl:allValuesFrom of hasDestination)
    synonyms: tuple[str, ...] = ()
    description: str = ""
    unnamed: str = "any"  # who does it when no robot is named: "any" (the one best robot) or "all"

    @property
    def priority(self) -> int:
        return PRIORITY[self.state]

    def missing(self, roles: set[str]) -> list[str]:
        """The binding needs this robot (with these bound roles) does not meet, in words."""
        return [" or ".join(group) for group in self.needs if not roles.intersection(group)]


DRIVE = (("move", "navigate"), ("odometry", "pose"))
PLACES = ("Location",)

ACTIONS: dict[str, Action] = {
    action.name: action
    for action in (
        Action(
            "move", "motion", State.MOTION, "execution.handlers.go_to", DRIVE, Stop.CANCEL,
            takes_destination=True, requires_destination=True, accepts=PLACES,
            synonyms=("shift", "go", "proceed", "walk", "advance", "head", "drive", "travel", "roll",
                      "relocate", "march", "come", "make your way", "head over"),
            description="drive to a destination",
        ),
        Action(
            "navigate", "motion", State.MOTION, "execution.handlers.go_to", DRIVE, Stop.CANCEL,
            takes_destination=True, requires_destination=True, accepts=PLACES,
            synonyms=("steer", "pilot", "find your way", "plan a path"),
            description="plan a path to a destination",
        ),
        Action(
            "rotate", "task", State.WORK, "execution.handlers.task", (("move",), ("odometry", "pose")),
            countable=True,
            synonyms=("turn", "spin", "revolve", "twirl", "pivot", "turn around", "spin around"),
            description="turn on the spot, n times",
        ),
        Action(
            "clean", "task", State.WORK, "execution.handlers.task", (("move",), ("odometry", "pose")),
            takes_destination=True, accepts=PLACES,
            synonyms=("sweep", "vacuum", "mop", "tidy", "wash", "hoover", "scrub", "tidy up"),
            description="clean where it is or at a destination",
        ),
        Action(
            "stop", "control", State.READY, None, stop=Stop.NONE,
            synonyms=("halt", "freeze", "cease", "pause", "stand still", "emergency stop", "e stop",
                      "hold on"),
            description="stop at once", unnamed="all",
        ),
        Action(
            "dock", "control", State.MOTION, "execution.handlers.dock", (("dock", "move", "navigate"),),
            Stop.CANCEL,
            synonyms=("go home", "return home", "go back home", "return to base", "go to base", "go to dock",
                      "go to the dock", "go back to base", "come home", "come back"),
            description="go to the robot's dock (its docking action where it has one) or its start pose",
        ),
        Action(
            "report_position", "query", State.DIALOG, "execution.handlers.report_position",
            (("odometry", "pose"),), Stop.NONE,
            synonyms=("locate", "where is", "where are", "where are you", "report position",
                      "report your position", "what is your position", "tell me where"),
            description="say where the robot is",
        ),
    )
}  # fmt: skip


class UnknownAction(KeyError):
    pass


def get(name: str) -> Action:
    """The registry entry for an action, or UnknownAction naming the known ones."""
    try:
        return ACTIONS[name]
    except KeyError:
        raise UnknownAction(f"unknown action {name!r}; known: {', '.join(sorted(ACTIONS))}") from None
