"""The forms beyond "who goes where": amounts, loops and subjects, applied to the parser's step drafts (no Django).

The parser fills slots word by word; these passes then settle what the slots mean together:
- an amount or a direction turns an action into its measured form (fleetcore.actions: `measured`):
  "move 2 meters forward" is move_by(2), "turn left" turn_by(90), "rotate 180 degrees" turn_by(180);
- a loop action (`loop_of`, patrol) over several destinations is one loop of visits, and a repeat repeats the
  steps before it: rounds said with a number are written out, "until stopped" ends in a repeat step;
- robots chosen by kind ("a turtlebot", "every robot except husky") are a subject object of the step contract.
And each step is read back in words (`read_back`): what the console's parse line and "Understood: ..." say.
"""

from __future__ import annotations

from dataclasses import replace

from fleetcore.actions import ACTIONS
from fleetcore.choice import ALL, ANY, ChoiceError, RobotChoice
from fleetcore.steps import StepError, parse_task

MEASURED_UNITS = ("m", "deg", "s")
MAX_STEPS = 200  # steps one instruction may expand to (a loop said with a number of rounds is written out)
AMOUNT_SHOWN = {"m": "{:g} m", "deg": "{:g}°", "s": "{:g} s", "times": "{:g} times"}


def measure(draft) -> tuple[list, str | None]:
    """The draft with its amount applied (maybe split in two: "move to A and turn left"); a stray amount's words."""
    unit = draft.unit or (draft.direction[0] if draft.direction else None)
    if unit is None:
        return [draft], None
    sign, default = 1, None
    if draft.direction and draft.direction[0] == unit:
        _, sign, default = draft.direction
    amount = draft.amount if draft.amount is not None else default
    if amount is not None:
        amount = sign * amount * (draft.count or 1)
    main, task = ACTIONS.get(draft.action or ""), ACTIONS.get(draft.task_action or "")
    if main is not None and main.unit == unit:
        draft.amount = amount if draft.amount is not None else None
        return [draft], None
    target = dict(main.measured).get(unit) if main else None
    if target and draft.dest is None and draft.task_action is None:
        draft.action, draft.amount, draft.count = target, amount, None
        return [draft], None
    task_target = dict(task.measured).get(unit) if task else None
    if task_target:
        extra = replace(
            draft,
            action=task_target,
            task_action=None,
            dest=None,
            amount=amount,
            count=None,
            continuation=True,
        )
        draft.task_action, draft.amount, draft.direction = None, None, None
        return [draft, extra], None
    if draft.amount is not None:
        return [draft], f"{draft.amount:g} {unit}"
    return [draft], None  # a direction that fits nothing here ("go back to A"): the destination says it


def mark_loops(drafts) -> dict[int, dict]:
    """Group the visits of each loop action (patrol A, B and C); return each loop's rounds."""
    loops: dict[int, dict] = {}
    current = None
    for draft in drafts:
        spec = ACTIONS.get(draft.action or "")
        if spec is None or spec.loop_of is None:
            current = None
            continue
        if current is None or not draft.inherited_action:
            current = len(loops)
            loops[current] = {"rounds": None, "forever": False, "drafts": []}
        loop = loops[current]
        loop["drafts"].append(draft)
        loop["rounds"] = loop["rounds"] or draft.count
        loop["forever"] = loop["forever"] or draft.forever
        draft.loop, draft.action, draft.count = current, spec.loop_of, None
    for loop in loops.values():
        _share_robots(loop["drafts"])
        loop["forever"] = loop["forever"] or not loop["rounds"]
    return loops


def _share_robots(drafts) -> None:
    """ "patrol A and B with tiago": the robots named anywhere in the loop do every visit."""
    named = [name for d in drafts for name in d.robots]
    if not named:
        return
    for draft in drafts:
        draft.robots = list(dict.fromkeys(named))


def expand(
    drafts, steps: list[dict], loops: dict[int, dict], max_steps: int
) -> tuple[list[dict], str | None]:
    """Write out the loops: rounds said with a number repeat the visits; "until stopped" ends in a repeat step.

    Returns the steps and, when it cannot, why ("nothing to repeat", too many steps).
    """
    out: list[dict] = []
    body_start, i = 0, 0
    while i < len(drafts):
        draft = drafts[i]
        if draft.loop is not None:
            j = i
            while j < len(drafts) and drafts[j].loop == draft.loop:
                j += 1
            loop = loops[draft.loop]
            out += _rounds(steps[i:j], None if loop["forever"] else loop["rounds"])
            body_start, i = len(out), j
            continue
        if draft.action == "repeat":
            body = out[body_start:]
            if not body:
                return out, "nothing_to_repeat"
            out += _rounds(body, None if draft.forever else max(draft.count or 2, 2))[len(body) :]
            body_start = len(out)
        else:
            out.append(steps[i])
        if len(out) > max_steps:
            return out, "too_many_steps"
        i += 1
    return out, ("too_many_steps" if len(out) > max_steps else None)


def _rounds(body: list[dict], rounds: int | None) -> list[dict]:
    """The body done `rounds` times in all, or once then a repeat step that loops until stopped."""
    if rounds is None:
        last = body[-1]
        repeat = {"action": "repeat", "robots": last["robots"], "destination": None, "task": None,
                  "speed": last["speed"], "span": len(body)}  # fmt: skip
        return [*body, repeat]
    return [dict(step) for _ in range(int(rounds)) for step in body]


def robots_of(draft, unnamed: str):
    """The step's robots: names, ALL, ANY, or a subject object ({"any": true, "model": "turtlebot"})."""
    if draft.robots:
        return [name for name in draft.robots if name not in draft.exclude] or list(draft.robots)
    mode = ALL if draft.all else ANY if draft.any else None
    if draft.model or draft.exclude:
        subject = {mode or (ALL if draft.exclude else ANY): True}
        if draft.model:
            subject["model"] = draft.model
        if draft.exclude:
            subject["except"] = list(draft.exclude)
        return subject
    return mode or unnamed


def read_back(step: dict) -> str:
    """The step in words: "rotate tiago 3 times", "move husky to B, then rotate 2 times", "move a robot the
    portal chooses to A", "turn_by tiago 90°". A task that is the step's own action is said with its count."""
    if step.get("instruction") is not None:  # "cancel #12"
        return f"{step.get('action')} #{step['instruction']}"
    words = [step.get("action") or "?", robots_in_words(step.get("robots"))]  # "?": an action not understood
    spec = ACTIONS.get(step.get("action") or "")
    if step.get("amount") is not None and spec is not None and spec.unit in AMOUNT_SHOWN:
        words.append(AMOUNT_SHOWN[spec.unit].format(step["amount"]))
    if step.get("span"):
        words.append(f"the {step['span']} step(s) before, until stopped")
    if step.get("destination"):
        at = "at" if spec is not None and spec.category == "task" else "to"  # clean tiago at Room 3
        words.append(f"{at} {_place_in_words(step['destination'])}")
    text = " ".join(words)
    if step.get("task"):
        name, times = _task(step["task"])
        times = f" {times:g} times" if times != 1 else ""
        text += times if name == step.get("action") else f", then {name}{times}"
    return text + (f", {step['speed']}" if step.get("speed") else "")


def robots_in_words(robots) -> str:
    """Names; ALL: "every robot"; ANY (none named): "a robot the portal chooses" (its answer says whom and why);
    a subject by kind: "a turtlebot the portal chooses", "every robot except husky"."""
    try:
        return RobotChoice.of(robots).words()
    except ChoiceError:  # the contract refuses it elsewhere
        return "a robot the portal chooses"


def _place_in_words(destination: dict) -> str:
    if destination.get("name"):
        return destination["name"]
    return f"({destination.get('x', 0):g}, {destination.get('y', 0):g})"


def _task(task: str) -> tuple[str, float]:
    try:
        return parse_task(task)
    except StepError:  # the contract refuses it elsewhere; say it as it came
        return str(task), 1
