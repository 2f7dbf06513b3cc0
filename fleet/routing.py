"""WebSocket routes: one socket per page."""

websocket_urlpatterns = []
