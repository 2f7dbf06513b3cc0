"""A simulated robot's diagnostic_msgs/DiagnosticArray, as its diagnostic nodes publish it on /diagnostics.

One status per component (battery, motors, odometry, laser), named "<namespace>/<component>" as
diagnostic_updater names them after their node, with the robot's name as hardware_id; levels as
diagnostic_msgs/DiagnosticStatus has them (OK 0, WARN 1, ERROR 2). The level follows what the robot is: a low
battery warns, below its reserve it is an error; odometry a test made bad is an error.
"""

from __future__ import annotations

OK, WARN, ERROR = 0, 1, 2
BATTERY_WARN, BATTERY_ERROR = 0.3, 0.15  # charge fractions below which the battery status warns, then errs


def _status(prefix: str, component: str, level: int, message: str, hardware_id: str, **values) -> dict:
    return {
        "level": level,
        "name": f"{prefix}{component}",
        "message": message,
        "hardware_id": hardware_id,
        "values": [{"key": key, "value": str(value)} for key, value in values.items()],
    }


def statuses(robot) -> list[dict]:
    """The statuses of one SimRobot now (its charge, its commanded speed, its odometry fault, its laser)."""
    prefix = f"{robot.ns.strip('/')}/" if robot.ns.strip("/") else ""
    name = robot.spec.name
    charge = robot.charge
    level = OK if charge >= BATTERY_WARN else WARN if charge >= BATTERY_ERROR else ERROR
    words = {OK: "ok", WARN: "low", ERROR: "critical"}[level]
    out = [
        _status(prefix, "battery", level, f"{words}: {charge * 100:.0f} %", name, percentage=round(charge, 3)),
        _status(prefix, "motors", OK, "driving" if abs(robot.body.vx) > 0.01 else "idle", name,
                linear=round(robot.body.vx, 3), angular=round(robot.body.wz, 3)),
    ]  # fmt: skip
    fault = robot.odom_fault
    out.append(_status(prefix, "odometry", ERROR if fault else OK, f"bad: {fault}" if fault else "ok", name))
    if robot.scan_topics:
        out.append(_status(prefix, "laser", OK, "ok", name, topic=robot.scan_topics[0]))
    return out


def array(robot, header: dict) -> dict:
    """The DiagnosticArray message one robot's diagnostics publish."""
    return {"header": header, "status": statuses(robot)}
