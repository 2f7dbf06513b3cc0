"""WebSocket routes: one socket per page."""

from django.urls import path

from portal import consumers

websocket_urlpatterns = [
    path("ws/fleet/", consumers.FleetConsumer.as_asgi()),
    path("ws/robots/<int:robot_id>/", consumers.RobotConsumer.as_asgi()),
    path("ws/alerts/", consumers.AlertsConsumer.as_asgi()),
]
