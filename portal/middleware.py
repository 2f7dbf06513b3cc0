"""Login everywhere: pages redirect to the login form, the API answers 401 itself."""

from django.contrib.auth.middleware import LoginRequiredMiddleware


class LoginRequired(LoginRequiredMiddleware):
    """Django's LoginRequiredMiddleware, except for /api/, whose own auth answers 401 (not a redirect)."""

    def process_view(self, request, view_func, view_args, view_kwargs):
        if request.path_info.startswith("/api/"):
            return None
        return super().process_view(request, view_func, view_args, view_kwargs)
