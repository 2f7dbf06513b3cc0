"""Robots entered by hand, as a person would (the paper's experiment 2): shared by the benchmarks that drive
the simulated robots through the portal (bench.run, bench.typed_stop)."""


def hand_register(links) -> dict[str, int]:
    """Robots entered by a person (the paper's experiment 2): no discovery, the known topics bound by hand."""
    from robots.models import Binding, Robot  # (the bench sets Django up after it imports its modules)

    ids = {}
    for link in links:
        pose = list(link.start)
        robot, _ = Robot.objects.update_or_create(
            name=link.name,
            defaults={
                "endpoint": link.url,
                "namespace": _namespace(link),
                "max_linear": link.max_linear,
                "max_angular": link.max_angular,
                "start_pose": pose,
                "link_status": Robot.Link.ONLINE,
                "state": Robot.State.READY,
            },
        )
        for action, target, type_ in (
            ("move", link.cmd_topic, "geometry_msgs/Twist"),
            ("odometry", link.odom_topic, "nav_msgs/Odometry"),
        ):
            Binding.objects.update_or_create(
                robot=robot,
                action=action,
                defaults={
                    "target": target,
                    "message_type": type_,
                    "how": Binding.How.USER,
                    "confidence": 1.0,
                },
            )
        ids[link.name] = robot.pk
    return ids


def _namespace(link) -> str:
    parts = link.cmd_topic.strip("/").split("/")
    return f"/{parts[0]}" if parts[0].startswith("robot") else ""
