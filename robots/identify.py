"""Which topic, action or service carries each action of a robot (the paper's Figure 12, made linear).

Each topic is looked at once: its type selects the actions it could serve (a type index, so the work is
linear in the number of topics, not the paper's O(n^4)), then a score adds up:
- 0.5 for the right message type on the right side of the graph (move: a Twist/TwistStamped somebody
  subscribes to; odometry: a nav_msgs/Odometry somebody publishes; navigate: a move_base / navigate_to_pose
  action server, or a PoseStamped goal topic somebody subscribes to; ...);
- +0.3 when the name (without the robot's namespace) is the action's canonical name ("cmd_vel", "odom",
  "amcl_pose", "move_base"): how = exact; +0.2 when only the last segment is ("mobile_base_controller/cmd_vel");
- +0.1 x weight for the best keyword of the paper's lists (cmd, vel, velocity, speed, travel, run; goal, amcl,
  odom, scan, map...) or of the database's TopicKeyword rows: how = pattern;
- +0.05 for an ontology synonym of the action in the name: how = synonym;
- graph facts: for odometry +0.25 when the robot's navigation stack subscribes to it (Husky: the EKF's
  /odometry/filtered over the controller's raw odometry); for move, the twist_mux rule below; for camera, +0.25
  for a .../compressed frame (TIAGo's /xtion/rgb/image_raw/compressed over its raw image), -0.3 for a depth
  image. The best candidate is bound with confidence = min(1, score). A tie, or no candidate
  for move or odometry, binds nothing: needs_user, with the candidates kept for a person. Optional actions
  (navigate, pose, scan, map, initial_pose, battery, dock, camera) with no candidate are simply absent, not a
  question.
- An action server whose type is a role's own (dock: irobot_create_msgs/action/Dock) scores as a topic would.

twist_mux rule (move). A node that subscribes two or more velocity topics and publishes one is a mux.
We bind one of its INPUTS, never its output: the output is the base controller's own input
(TIAGo /mobile_base_controller/cmd_vel, Husky /husky_velocity_controller/cmd_vel); publishing there races the
mux and bypasses its priorities, timeouts and locks (e-stop, pause_navigation). Among the inputs we prefer the
robot's designated external input: the one its own navigation stack publishes to (move_base or nav2's
controller/velocity smoother: TIAGo /nav_vel, priority 10; Husky /cmd_vel, priority 1), then one named
"cmd_vel". So a person on the robot's joystick or keyboard input (higher priority) can always override the
web, as the vendors intend. Scores: mux output -0.3, mux input +0.1, published by the navigation stack
+0.15, input named for navigation (nav) +0.05, published by a teleop node (joy, teleop, marker) -0.1.
Without a navigation stack TIAGo's inputs (nav_vel, key_vel, joy_vel...) tie on everything but the "nav"
hint, which settles it; a mux whose inputs truly tie goes to a person.
A choice a person made (how = user) is kept while its target still exists.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

from fleetcore.bindings import ESSENTIAL as ESSENTIAL_ROLES
from fleetcore.bindings import NAV_ACTION_SERVERS, RECONFIGURE, ROLES
from robots.discovery import Graph, decode_param, norm_type

ACTIONS = tuple(ROLES)  # the binding roles (fleetcore/bindings.py): the one table of types and keywords
ESSENTIAL = set(ESSENTIAL_ROLES)
TIE = 1e-6
MAX_WEIGHT = 1.5  # a TopicKeyword weight counts at most this much, so names never outweigh graph facts


RULES = ROLES
NAV_ACTIONS = NAV_ACTION_SERVERS
DEFAULT_KEYWORDS = {role.name: dict(role.keywords) for role in ROLES.values()}
DEFAULT_SYNONYMS = {role.name: set(role.synonyms) for role in ROLES.values() if role.synonyms}
# The action servers navigate can drive (types as norm_type spells them): ROS 1 move_base, ROS 2 Nav2.
NAV_ACTION_TYPES = frozenset({"move_base_msgs/MoveBaseAction", "nav2_msgs/NavigateToPose"})


def accepts(action: str, kind: str, type_: str) -> bool:
    """Whether a binding of `action` may point at a `kind` ("topic", "action") of this type."""
    rule = RULES.get(action)
    if rule is None:
        return False
    type_ = norm_type(type_)
    if kind == "topic":
        return type_ in rule.types
    if kind == "service":
        return action == "speed_limit" and type_ == RECONFIGURE
    if kind != "action":
        return False
    return (action == "navigate" and type_ in NAV_ACTION_TYPES) or type_ in rule.types  # dock: its own type


def accepted(action: str) -> str:
    """What a binding of `action` may point at, in words, for a refusal."""
    rule = RULES.get(action)
    if rule is None:
        return "nothing (not an action)"
    topics = " or ".join(sorted(rule.types))
    servers = " or ".join(sorted(NAV_ACTION_TYPES)) if action == "navigate" else ""
    service = f", or a {RECONFIGURE} service (a local planner's)" if action == "speed_limit" else ""
    return f"a {topics} topic" + (f", or a {servers} action server" if servers else "") + service


NAV_NODES = {"move_base", "controller_server", "velocity_smoother", "bt_navigator"}
TELEOP_WORDS = ("teleop", "joy", "marker", "keyboard")


@dataclass
class Vocabulary:
    keywords: dict[str, dict[str, float]] = field(
        default_factory=lambda: {a: dict(k) for a, k in DEFAULT_KEYWORDS.items()}
    )
    synonyms: dict[str, set[str]] = field(
        default_factory=lambda: {a: set(s) for a, s in DEFAULT_SYNONYMS.items()}
    )


@dataclass
class Candidate:
    target: str
    type: str
    kind: str
    score: float
    how: str


@dataclass
class Result:
    action: str
    target: str = ""
    kind: str = "topic"
    message_type: str = ""
    how: str = "none"
    confidence: float = 0.0
    needs_user: bool = False
    candidates: list[dict] = field(default_factory=list)


@dataclass
class Facts:
    """Graph facts computed once per robot: twist_mux inputs and outputs, navigation and teleop outputs."""

    mux_inputs: set[str] = field(default_factory=set)
    mux_outputs: set[str] = field(default_factory=set)
    nav_published: set[str] = field(default_factory=set)
    nav_subscribed: set[str] = field(default_factory=set)
    teleop_published: set[str] = field(default_factory=set)


def graph_facts(graph: Graph) -> Facts:
    facts = Facts()
    velocity = {n for n, t in graph.topics.items() if norm_type(t.type) in RULES["move"].types}
    for node, detail in graph.nodes.items():
        subs = velocity.intersection(detail.get("subscribing", ()))
        pubs = velocity.intersection(detail.get("publishing", ()))
        if len(subs) >= 2 and pubs:
            facts.mux_inputs |= subs
            facts.mux_outputs |= pubs
        last = node.rsplit("/", 1)[-1]
        if last in NAV_NODES:
            facts.nav_published |= set(detail.get("publishing", ()))
            facts.nav_subscribed |= set(detail.get("subscribing", ()))
        if any(word in node for word in TELEOP_WORDS):
            facts.teleop_published |= pubs
    return facts


def tokens(relative: str) -> set[str]:
    segments = [s for s in relative.split("/") if s]
    return set(segments) | {part for s in segments for part in s.split("_") if part}


def name_score(
    relative: str, action: str, vocab: Vocabulary, canonical: tuple[str, ...]
) -> tuple[float, str]:
    """Score a name for an action and say how it matched (exact always beats last-segment by 0.2)."""
    words = tokens(relative)
    score, how = 0.0, ""
    if relative in canonical:
        score, how = 0.4, "exact"
    elif relative.rsplit("/", 1)[-1] in canonical:
        score, how = 0.2, "pattern"
    weights = [min(w, MAX_WEIGHT) for k, w in vocab.keywords.get(action, {}).items() if k in words]
    if weights:
        score, how = score + 0.1 * max(weights), how or "pattern"
    if not how and words & vocab.synonyms.get(action, set()):
        score, how = score + 0.05, "synonym"
    return score, how or "pattern"


def _move_facts(name: str, facts: Facts) -> float:
    bonus = 0.1 if name in facts.mux_inputs else 0.0
    bonus -= 0.3 if name in facts.mux_outputs else 0.0
    bonus += 0.15 if name in facts.nav_published else 0.0
    bonus -= 0.1 if name in facts.teleop_published else 0.0
    if name in facts.mux_inputs and "nav" in tokens(name.rsplit("/", 1)[-1]):
        bonus += 0.05
    return bonus


def _odometry_facts(name: str, facts: Facts) -> float:
    """The odometry the robot's own navigation listens to is the one it trusts (Husky: the EKF's)."""
    return 0.25 if name in facts.nav_subscribed else 0.0


def _map_facts(name: str, facts: Facts) -> float:
    return -0.3 if "costmap" in name else 0.0


def _camera_facts(name: str, facts: Facts) -> float:
    """A camera's image_transport compressed form before its raw frames (a browser shows it as it comes, at a
    fraction of the size); a depth image is no photo."""
    return (0.25 if name.endswith("/compressed") else 0.0) - (0.3 if "depth" in name.lower() else 0.0)


FACT_RULES = {"move": _move_facts, "odometry": _odometry_facts, "map": _map_facts, "camera": _camera_facts}


def candidates(graph: Graph, vocab: Vocabulary) -> dict[str, list[Candidate]]:
    """Score every topic once for the actions its type can serve; add action servers for dock and navigate."""
    facts = graph_facts(graph)
    by_type: dict[str, list[str]] = {}
    for action, rule in RULES.items():
        for type_ in rule.types:
            by_type.setdefault(type_, []).append(action)
    found: dict[str, list[Candidate]] = {a: [] for a in ACTIONS}
    for name, info in graph.topics.items():
        for action in by_type.get(norm_type(info.type), ()):
            rule = RULES[action]
            if not (info.subscribers if rule.side == "sub" else info.publishers):
                continue
            if action == "navigate" and name not in facts.nav_subscribed:
                continue  # a goal topic no navigation stack consumes (Spot's body-frame go_to_pose) moves nothing
            score, how = name_score(graph.relative(name), action, vocab, rule.canonical)
            extra = FACT_RULES.get(action)
            total = 0.5 + score + (extra(name, facts) if extra else 0.0)
            found[action].append(Candidate(name, info.type, "topic", round(total, 4), how))
    for name, type_ in graph.actions.items():
        relative = graph.relative(name)
        for action in by_type.get(norm_type(type_), ()):  # a server of the role's own type (dock: Create 3's)
            score, how = name_score(relative, action, vocab, RULES[action].canonical)
            found[action].append(Candidate(name, type_, "action", round(0.5 + score, 4), how))
        score, how = name_score(relative, "navigate", vocab, NAV_ACTIONS)
        if not accepts("navigate", "action", type_) or (score <= 0.1 and "navigat" not in relative):
            continue  # another action server (arm, spin, dock), or one whose goals we cannot send
        bonus = 0.1 if any(k in type_ for k in ("MoveBase", "NavigateToPose")) else 0.0
        found["navigate"].append(Candidate(name, type_, "action", round(0.6 + score + bonus, 4), how))
    found["speed_limit"] += local_planners(graph)
    return found


def local_planners(graph: Graph) -> list[Candidate]:
    """move_base's local planner's dynamic_reconfigure service (`<move_base>/<plugin class>/set_parameters`, the
    plugin named by the `base_local_planner` param): where a ROS 1 navigation stack takes its top speed."""
    out = []
    for name, value in graph.params.items():
        plugin = decode_param(value) if name.endswith("/base_local_planner") else None
        if not isinstance(plugin, str) or not plugin:
            continue
        service = f"{name.removesuffix('/base_local_planner')}/{plugin.rsplit('/', 1)[-1]}/set_parameters"
        if norm_type(graph.services.get(service, "")) == RECONFIGURE:
            out.append(Candidate(service, graph.services[service], "service", 0.9, "exact"))
    return out


def identify(
    graph: Graph, vocab: Vocabulary | None = None, user_choices: dict[str, str] | None = None
) -> dict[str, Result]:
    """Bind every action of one robot; keep a person's choice while its target still exists."""
    vocab = vocab or Vocabulary()
    found = candidates(graph, vocab)
    results = {}
    for action in ACTIONS:
        ranked = sorted(found[action], key=lambda c: (-c.score, c.target))
        kept = [asdict(c) for c in ranked[:10]]
        choice = (user_choices or {}).get(action)
        if choice and (target := _lookup(graph, action, choice)):
            kind, type_ = target
            results[action] = Result(action, choice, kind, type_, "user", 1.0, False, kept)
        elif not ranked:
            results[action] = Result(action, needs_user=action in ESSENTIAL)
        elif len(ranked) > 1 and ranked[0].score - ranked[1].score < TIE:
            results[action] = Result(action, how="none", needs_user=True, candidates=kept)
        else:
            best = ranked[0]
            conf = round(min(1.0, best.score), 2)
            results[action] = Result(action, best.target, best.kind, best.type, best.how, conf, False, kept)
    return results


def _lookup(graph: Graph, action: str, target: str) -> tuple[str, str] | None:
    """(kind, type) of a person's earlier choice while the graph still has it with a type the action takes."""
    if target in graph.topics:
        found = "topic", graph.topics[target].type
    elif target in graph.actions:
        found = "action", graph.actions[target]
    elif target in graph.services:
        found = "service", graph.services[target]
    else:
        return None
    return found if accepts(action, *found) else None
