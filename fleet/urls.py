from django.contrib import admin
from django.contrib.auth import views as auth_views
from django.urls import include, path

from portal.api import api

urlpatterns = [
    path("login/", auth_views.LoginView.as_view(redirect_authenticated_user=True), name="login"),
    path("logout/", auth_views.LogoutView.as_view(), name="logout"),
    path("admin/", admin.site.urls),
    path("api/", api.urls),
    path("", include("portal.urls")),
]

handler500 = (
    "portal.middleware.server_error"  # a store refusing, raised outside a view, is a 503 with its reason
)
