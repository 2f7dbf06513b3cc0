"""The portal's pages and their small POST views."""

from django.urls import path

from portal import views, views_experiments, views_recordings

urlpatterns = [
    path("", views.dashboard, name="dashboard"),
    path("robots/", views.robot_list, name="robot-list"),
    path("robots/<int:pk>/", views.robot_detail, name="robot-detail"),
    path("robots/<int:pk>/lease/", views.lease, name="robot-lease"),
    path("robots/<int:pk>/release/", views.release_hold, name="robot-release-hold"),
    path("robots/<int:pk>/teleop/", views.teleop, name="robot-teleop"),
    path("register/", views.registration, name="registration"),
    path("register/bindings/<int:pk>/", views.choose_binding, name="choose-binding"),
    path("schedules/", views.schedules, name="schedules"),
    path("history/", views.history, name="history"),
    path("photos/<int:pk>/", views.photo, name="photo"),
    path("audit/", views.audit, name="audit"),
    path("alerts/", views.alerts, name="alerts"),
    path("experiments/", views_experiments.experiments, name="experiments"),
    path("experiments/status/", views_experiments.runs_status, name="experiment-status"),
    path(
        "experiments/tables.csv",
        views_experiments.tables_export,
        {"fmt": "csv"},
        name="experiment-tables-csv",
    ),
    path(
        "experiments/tables.json",
        views_experiments.tables_export,
        {"fmt": "json"},
        name="experiment-tables-json",
    ),
    path(
        "experiments/runs/<int:pk>.csv",
        views_experiments.run_export,
        {"fmt": "csv"},
        name="experiment-run-csv",
    ),
    path(
        "experiments/runs/<int:pk>.json",
        views_experiments.run_export,
        {"fmt": "json"},
        name="experiment-run-json",
    ),
    path("recordings/", views_recordings.recordings, name="recordings"),
    path("recordings/<int:pk>/", views_recordings.replay, name="recording-replay"),
    path("recordings/<int:pk>/frames.json", views_recordings.frames, name="recording-frames"),
    path("recordings/<int:pk>/recording.mcap", views_recordings.download, name="recording-download"),
    path("control/stop/", views.stop, name="stop"),
]
