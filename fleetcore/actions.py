"""The action registry: everything about one action a person can ask for, in one entry (no Django).

An entry holds the ontology term (category, destination rules, synonyms: the interpreter seeds its ontology
from it), the binding roles a robot needs to do it (fleetcore/bindings.py), the state the robot is in while it
runs (its priority follows: work > motion > dialog), the executor's handler (its name in the executor's table,
`execution.handlers.HANDLERS`, which holds the functions themselves: no dotted path is imported). Adding an action is adding an entry here and its handler. How a stop ends it is no field of an
entry: a stop stops the robot whatever runs (a zero velocity and a move_base cancel, robots/commands.py's
CommandSurface.zero; then the stop flag, on which the runner cancels a ROS 2 navigation goal).
"""

from __future__ import annotations

from dataclasses import dataclass

from fleetcore.states import PRIORITY, State


@dataclass(frozen=True)
class Action:
    name: str
    category: str  # ontology category: motion | task | control | query
    state: State  # the robot's state while the action runs
    handler: str | None  # the executor's handler, by name (execution.handlers.HANDLERS); None: not run by it
    needs: tuple[tuple[str, ...], ...] = ()  # binding roles: every group needed, any role of a group will do
    takes_destination: bool = False
    requires_destination: bool = False
    countable: bool = False
    accepts: tuple[str, ...] = ()  # destination classes (owl:allValuesFrom of hasDestination)
    synonyms: tuple[str, ...] = ()
    description: str = ""
    unnamed: str = "any"  # who does it when no robot is named: "any" (the one best robot) or "all"
    unit: str | None = (
        None  # what the step's amount measures (fleetcore.steps.UNITS): "m", "deg", "s", "times"
    )
    measured: tuple[tuple[str, str], ...] = ()  # said with an amount of this unit, it is that action instead
    loop_of: str | None = None  # a loop over its destinations: each visit is a step of this action (patrol)
    # a number said with it names an instruction ("cancel #12"): the step's "instruction"
    names_instruction: bool = False

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
            "move", "motion", State.MOTION, "go_to", DRIVE,
            takes_destination=True, requires_destination=True, accepts=PLACES,
            synonyms=("shift", "go", "proceed", "walk", "advance", "head", "drive", "travel", "roll",
                      "relocate", "march", "come", "make your way", "head over", "send", "dispatch"),
            description="drive to a destination", measured=(("m", "move_by"),),
        ),
        Action(
            "navigate", "motion", State.MOTION, "go_to", DRIVE,
            takes_destination=True, requires_destination=True, accepts=PLACES,
            synonyms=("steer", "pilot", "find your way", "plan a path"),
            description="plan a path to a destination", measured=(("m", "move_by"),),
        ),
        Action(
            "rotate", "task", State.WORK, "task", (("move",), ("odometry", "pose")),
            countable=True,
            synonyms=("turn", "spin", "revolve", "twirl", "pivot", "spin around"),
            description="turn on the spot, n times", measured=(("deg", "turn_by"),),
        ),
        Action(
            "clean", "task", State.WORK, "task", (("move",), ("odometry", "pose")),
            takes_destination=True, accepts=PLACES,
            synonyms=("sweep", "vacuum", "mop", "tidy", "wash", "hoover", "scrub", "tidy up"),
            description="clean where it is or at a destination",
        ),
        Action(
            "photograph", "task", State.WORK, "photograph", (("camera",),),
            synonyms=("take a photo", "take a picture", "take a photograph", "take a snapshot", "snap a photo",
                      "snap a picture", "snap", "capture", "photo", "picture", "snapshot"),
            description="take a photo with the robot's camera, where it stands (kept with the instruction)",
        ),
        Action(
            "stop", "control", State.READY, None,
            synonyms=("halt", "freeze", "cease", "pause", "stand still", "emergency stop", "e stop",
                      "hold on"),
            description="stop at once", unnamed="all",
        ),
        Action(
            "dock", "control", State.MOTION, "dock", (("dock", "move", "navigate"),),
            synonyms=("go home", "return home", "go back home", "return to base", "go to base", "go to dock",
                      "go to the dock", "go back to base", "come home", "come back", "head home", "drive home",
                      "return to your start", "return to start", "return to the start", "go back to start",
                      "go back to your start", "come back to your start", "come back to start",
                      "go back to where you started", "return to where you started",
                      "come back to where you started", "back to where you started", "back to your start",
                      "go to your start", "return to your starting point", "go back to your starting point",
                      "return to your start position", "go back to the start"),
            description="go to the robot's dock (its docking action where it has one) or its start pose",
        ),
        Action(
            "make_way", "motion", State.MOTION, "make_way", DRIVE,
            synonyms=("make way", "make room", "give way", "clear the way", "get out of the way", "step aside"),
            description="move off the way of a robot waiting for it, and come back once it has passed",
            unnamed="all",
        ),
        Action(
            "release", "control", State.READY, None,
            synonyms=("let go", "unhold", "unfreeze", "release the hold on", "let it move again"),
            description="let robots a person's stop holds move again (nothing automatic moves them till then)",
            unnamed="all",
        ),
        Action(
            "cancel", "control", State.READY, None,
            synonyms=("abort", "call off", "scrap", "withdraw", "revoke"),
            description="cancel one instruction ('cancel #12', or what a robot runs: 'cancel husky's instruction'):"
            " its robot comes to rest, what waits behind it runs next", names_instruction=True,
        ),
        Action(
            "report_position", "query", State.DIALOG, "report_position",
            (("odometry", "pose"),),
            synonyms=("locate", "where is", "where are", "where are you", "report position",
                      "report your position", "what is your position", "tell me where"),
            description="say where the robot is",
        ),
        Action(
            "move_by", "motion", State.MOTION, "move_by", DRIVE, unit="m",
            synonyms=("move by", "drive by", "go by"),
            description="drive straight ahead (or back, when negative) by a distance in metres",
        ),
        Action(
            "turn_by", "motion", State.MOTION, "turn_by", (("move",), ("odometry", "pose")),
            unit="deg", synonyms=("turn by", "rotate by", "spin by"),
            description="turn on the spot by an angle in degrees (left, anticlockwise, when positive)",
        ),
        Action(
            "wait", "control", State.MOTION, "wait", (), unit="s",
            synonyms=("hold", "linger", "stay", "stand by", "rest", "idle", "sleep", "remain", "stay put",
                      "wait there", "hang on"),
            description="stay where it is for a number of seconds",
        ),
        Action(
            "repeat", "control", State.MOTION, "repeat", (), unit="times", countable=True,
            synonyms=("do it again", "loop", "keep going", "keep repeating", "do that again"),
            description="do the steps before it again (a number of times, or until stopped)",
        ),
        Action(
            "patrol", "motion", State.MOTION, None, DRIVE,
            takes_destination=True, requires_destination=True, accepts=PLACES, countable=True, loop_of="move",
            synonyms=("go back and forth", "shuttle", "circulate", "make rounds", "do rounds", "go round",
                      "guard", "keep watch over", "tour", "cycle through", "loop through"),
            description="visit the places in turn, round after round (until stopped unless rounds are said)",
        ),
        Action(
            "report_status", "query", State.DIALOG, None,
            synonyms=("what is", "what's", "whats", "what are", "status", "status of", "state of",
                      "report status", "how is", "how are", "what is the status of", "is busy", "busy"),
            description="say what the robot is doing",
        ),
        Action(
            "list_free", "query", State.DIALOG, None, unnamed="all",
            synonyms=("which robots are free", "which robot is free", "which are free", "who is free",
                      "which robots are available", "which robot is available", "which robots are idle",
                      "list free robots", "free robots", "available robots", "idle robots", "is anyone free",
                      "is any robot free", "are any robots free", "who is available", "which ones are free"),
            description="say which robots are free to take an instruction",
        ),
        Action(
            "report_distance", "query", State.DIALOG, None, takes_destination=True,
            requires_destination=True, accepts=PLACES,
            synonyms=("how far", "how far away", "distance", "distance of", "how far is it"),
            description="say how far the robot is from a place (its planned path and the straight line)",
        ),
        Action(
            "list_abilities", "query", State.DIALOG, None,
            synonyms=("what can", "capabilities", "capabilities of", "abilities of", "what are the abilities of",
                      "what is able to do", "skills of"),
            description="say which actions the robot can do with what it has bound",
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
