"""The portal's pages."""

from django.urls import path

from fleet import views

urlpatterns = [
    path("", views.dashboard, name="dashboard"),
]
