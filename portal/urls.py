"""The portal's pages and their small POST views."""

from django.urls import path

from portal import views, views_experiments

urlpatterns = [
    path("", views.dashboard, name="dashboard"),
    path("robots/", views.robot_list, name="robot-list"),
    path("robots/<int:pk>/", views.robot_detail, name="robot-detail"),
    path("robots/<int:pk>/lease/", views.lease, name="robot-lease"),
    path("robots/<int:pk>/teleop/", views.teleop, name="robot-teleop"),
    path("register/", views.registration, name="registration"),
    path("register/bindings/<int:pk>/", views.choose_binding, name="choose-binding"),
    path("schedules/", views.schedules, name="schedules"),
    path("history/", views.history, name="history"),
    path("audit/", views.audit, name="audit"),
    path("alerts/", views.alerts, name="alerts"),
    path("experiments/", views_experiments.experiments, name="experiments"),
    path("control/stop/", views.stop, name="stop"),
]
