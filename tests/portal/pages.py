"""Every page a person opens, for the tests that walk them all (security headers, CSP, phone widths)."""

from recordings.models import Recording


def every_page(robot, tmp_path) -> dict[str, str]:
    """Name -> path of every page (a finished recording made for the replay); the login page last."""
    from recordings.mcapfile import RecordingWriter

    path = tmp_path / "pages.mcap"
    writer = RecordingWriter(path)
    writer.pose(robot.name, 0.5, 0.5, 0.0, 1.0)
    writer.close()
    replay = Recording.objects.create(seconds=1, path=str(path), status="finished", counts={"pose": 1})
    return {
        "dashboard": "/",
        "robots": "/robots/",
        "robot": f"/robots/{robot.pk}/",
        "registration": "/register/",
        "schedules": "/schedules/",
        "history": "/history/",
        "experiments": "/experiments/",
        "recordings": "/recordings/",
        "replay": f"/recordings/{replay.pk}/",
        "alerts": "/alerts/",
        "audit": "/audit/",
        "api-docs": "/api/docs",
        "admin": "/admin/",
    }
