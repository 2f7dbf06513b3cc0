"""Facts a registration needs from a URDF: robot name, wheels or legs, footprint (no Django).

Rules (the paper's Figure 3 asks "has wheels?" then "which legs?"):
- a wheel is a continuous joint whose joint name or child link name contains "wheel"; casters
  (name contains "caster") are not driven wheels;
- a leg joint is a revolute joint named like hip/knee/ankle/thigh/calf/shin/leg; legged when there are at
  least four, with the leg count taken from the distinct prefixes before the joint part (front_left_...);
- the footprint is the base link's collision box (centred at its origin) or a cylinder's bounding square.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import asdict, dataclass, field

LEG_PARTS = ("hip", "knee", "ankle", "thigh", "calf", "shin", "leg", "haa", "hfe", "kfe")
BASE_LINKS = ("base_link", "base_footprint", "body", "base", "chassis_link")


class URDFError(ValueError):
    """A robot_description that is not a usable URDF; the message says why in one line."""


@dataclass
class URDFFacts:
    name: str = ""
    wheel_joints: list[str] = field(default_factory=list)
    leg_joints: list[str] = field(default_factory=list)
    leg_count: int = 0
    footprint: list[list[float]] = field(default_factory=list)
    joint_count: int = 0

    @property
    def wheel_count(self) -> int:
        return len(self.wheel_joints)

    @property
    def drive(self) -> str:
        if self.wheel_joints:
            return "wheeled"
        if self.leg_count >= 2:
            return "legged"
        return "other"

    def as_dict(self) -> dict:
        return {**asdict(self), "wheel_count": self.wheel_count, "drive": self.drive}


def parse(text: str) -> URDFFacts:
    """Parse URDF text; raise URDFError naming the problem."""
    if not isinstance(text, str) or not text.strip():
        raise URDFError("robot_description is empty")
    try:
        root = ET.fromstring(text.strip())
    except ET.ParseError as exc:
        raise URDFError(f"robot_description is not XML ({exc})") from None
    if root.tag != "robot":
        raise URDFError(f"robot_description's root element is <{root.tag}>, not <robot>")
    joints = root.findall("joint")
    facts = URDFFacts(name=root.get("name", ""), joint_count=len(joints))
    for joint in joints:
        name, kind = joint.get("name", ""), joint.get("type", "")
        child = (joint.find("child").get("link", "") if joint.find("child") is not None else "").lower()
        lowered = name.lower()
        if (
            kind == "continuous"
            and ("wheel" in lowered or "wheel" in child)
            and "caster" not in lowered + child
        ):
            facts.wheel_joints.append(name)
        elif kind == "revolute" and any(part in lowered for part in LEG_PARTS):
            facts.leg_joints.append(name)
    facts.leg_count = _leg_count(facts.leg_joints) if len(facts.leg_joints) >= 4 else 0
    facts.footprint = _footprint(root)
    return facts


def _leg_count(joints: list[str]) -> int:
    """Count legs as the distinct name prefixes before the first leg-part word."""
    legs = set()
    for joint in joints:
        tokens = joint.lower().split("_")
        cut = next((i for i, t in enumerate(tokens) if any(p in t for p in LEG_PARTS)), len(tokens))
        legs.add("_".join(tokens[:cut]))
    return len(legs)


def _footprint(root: ET.Element) -> list[list[float]]:
    links = {link.get("name"): link for link in root.findall("link")}
    for name in BASE_LINKS:
        link = links.get(name)
        geometry = link.find("collision/geometry") if link is not None else None
        if geometry is None:
            continue
        box, cylinder = geometry.find("box"), geometry.find("cylinder")
        try:
            if box is not None:
                sx, sy, _ = (float(v) for v in box.get("size", "").split())
                return _rectangle(sx / 2, sy / 2, _origin_x(link))
            if cylinder is not None:
                r = float(cylinder.get("radius", "0"))
                return _rectangle(r, r, _origin_x(link))
        except ValueError:
            return []
    return []


def _origin_x(link: ET.Element) -> float:
    origin = link.find("collision/origin")
    try:
        return float(origin.get("xyz", "0 0 0").split()[0]) if origin is not None else 0.0
    except (ValueError, IndexError):
        return 0.0


def _rectangle(hx: float, hy: float, cx: float) -> list[list[float]]:
    return [[round(cx - hx, 4), round(-hy, 4)], [round(cx - hx, 4), round(hy, 4)],
            [round(cx + hx, 4), round(hy, 4)], [round(cx + hx, 4), round(-hy, 4)]]  # fmt: skip
