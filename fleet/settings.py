"""Settings for the fleet portal, all from the environment through fleet/env.py.

Defaults work on a laptop with nothing installed: a SQLite file and an embedded Redis, both under var/.
"""

import os
import warnings
from pathlib import Path

from fleet.env import (
    celery_broker_url,
    channels_host,
    env_bool,
    env_database,
    env_list,
    env_redis_url,
    env_secret_key,
    env_str,
)

BASE_DIR = Path(__file__).resolve().parent.parent
VAR_DIR = Path(os.environ.get("FLEET_VAR_DIR", BASE_DIR / "var"))
VAR_DIR.mkdir(parents=True, exist_ok=True)

SECRET_KEY = env_secret_key("SECRET_KEY", VAR_DIR / "secret_key")
DEBUG = env_bool("FLEET_DEBUG", default=False)
ALLOWED_HOSTS = env_list("ALLOWED_HOSTS", ["127.0.0.1", "localhost", "[::1]", "testserver"])
CSRF_TRUSTED_ORIGINS = [f"http://{host}:8000" for host in ALLOWED_HOSTS if host not in {"*", "testserver"}]

REDIS_URL = env_redis_url("REDIS_URL", VAR_DIR / "redis.sock")
EMBEDDED_REDIS = "REDIS_URL" not in os.environ or not os.environ["REDIS_URL"]

INSTALLED_APPS = [
    "django.contrib.admin",
    "django.contrib.auth",
    "django.contrib.contenttypes",
    "django.contrib.sessions",
    "django.contrib.messages",
    "django.contrib.staticfiles",
    "channels",
    "fleet",
    "robots",
    "interpreter",
    "simworker",
]

MIDDLEWARE = [
    "django.middleware.security.SecurityMiddleware",
    "whitenoise.middleware.WhiteNoiseMiddleware",
    "django.contrib.sessions.middleware.SessionMiddleware",
    "django.middleware.common.CommonMiddleware",
    "django.middleware.csrf.CsrfViewMiddleware",
    "django.contrib.auth.middleware.AuthenticationMiddleware",
    "fleet.middleware.LoginRequired",
    "django.contrib.messages.middleware.MessageMiddleware",
    "django.middleware.clickjacking.XFrameOptionsMiddleware",
]

ROOT_URLCONF = "fleet.urls"
ASGI_APPLICATION = "fleet.asgi.application"

TEMPLATES = [
    {
        "BACKEND": "django.template.backends.django.DjangoTemplates",
        "DIRS": [BASE_DIR / "templates"],
        "APP_DIRS": True,
        "OPTIONS": {
            "context_processors": [
                "django.template.context_processors.request",
                "django.contrib.auth.context_processors.auth",
                "django.contrib.messages.context_processors.messages",
                "fleet.roles.context_processor",
            ],
        },
    },
]

DATABASES = {"default": env_database("DATABASE_URL", VAR_DIR / "fleet.sqlite3")}
DEFAULT_AUTO_FIELD = "django.db.models.BigAutoField"

CACHES = {
    "default": {
        "BACKEND": "django.core.cache.backends.redis.RedisCache",
        "LOCATION": REDIS_URL,
        "KEY_PREFIX": os.environ.get("FLEET_REDIS_PREFIX", "fleet"),
    }
}

CHANNEL_LAYERS = {
    "default": {
        "BACKEND": "channels_redis.core.RedisChannelLayer",
        "CONFIG": {
            "hosts": [channels_host(REDIS_URL)],
            "capacity": 1000,
            "expiry": 10,
            # Separate runs on one Redis (e.g. two test runs) never hear each other's pushes.
            "prefix": os.environ.get("FLEET_REDIS_PREFIX", "fleet") + ":asgi",
        },
    }
}

CELERY_BROKER_URL = celery_broker_url(REDIS_URL)
CELERY_RESULT_BACKEND = celery_broker_url(REDIS_URL)
# A task survives its worker's death: acknowledged only once it has ended, given back to the queue when the worker
# process is lost, taken one at a time; a task delivered again finds its own claims and does nothing twice.
CELERY_TASK_ACKS_LATE = True
CELERY_TASK_REJECT_ON_WORKER_LOST = True
CELERY_WORKER_PREFETCH_MULTIPLIER = 1
CELERY_TASK_DEFAULT_QUEUE = "instructions"
CELERY_IMPORTS = ["fleet.experiments"]  # tasks outside the apps' tasks.py modules
CELERY_TASK_ROUTES = {
    "robots.tasks.*": {"queue": "registration"},
    "simworker.tasks.*": {"queue": "sim"},
    "fleet.tasks.stop_*": {"queue": "control"},
    "fleet.tasks.*": {"queue": "instructions"},
}
# Redis lost and back: workers retry the broker for ever (Celery's default gives up after 100 tries and exits), and
# a connection that went quiet is found by a PING every 10 s. A message taken but never acknowledged (its worker
# was killed, or Redis went away under it) is delivered again after the visibility timeout, which must be longer
# than the longest task: one instruction's run, whose steps each end within a time that follows from their distance
# (minutes on the demo maps), so an hour.
CELERY_BROKER_CONNECTION_RETRY = True
CELERY_BROKER_CONNECTION_RETRY_ON_STARTUP = True
CELERY_BROKER_CONNECTION_MAX_RETRIES = None
CELERY_BROKER_TRANSPORT_OPTIONS = {
    "visibility_timeout": 3600,
    "health_check_interval": 10,
    "retry_on_timeout": True,
}
# A running instruction drives its robots over rosbridge, not Redis: a broker outage does not cancel it (its late
# acknowledgement may fail; the redelivery then finds it finished).
CELERY_WORKER_CANCEL_LONG_RUNNING_TASKS_ON_CONNECTION_LOSS = False
CELERY_RESULT_BACKEND_ALWAYS_RETRY = True
CELERY_RESULT_BACKEND_MAX_RETRIES = 10
CELERY_REDIS_BACKEND_HEALTH_CHECK_INTERVAL = 10
CELERY_REDIS_RETRY_ON_TIMEOUT = True

AUTH_PASSWORD_VALIDATORS = [
    {"NAME": "django.contrib.auth.password_validation.MinimumLengthValidator", "OPTIONS": {"min_length": 8}},
]
LOGIN_URL = "login"
LOGIN_REDIRECT_URL = "dashboard"
LOGOUT_REDIRECT_URL = "login"

LANGUAGE_CODE = "en-us"
TIME_ZONE = os.environ.get("TZ", "UTC")
USE_I18N = False
USE_TZ = True

STATIC_URL = "static/"
STATICFILES_DIRS = [BASE_DIR / "static"]
STATIC_ROOT = VAR_DIR / "static"
STATIC_ROOT.mkdir(exist_ok=True)
# WhiteNoise serves files with a synchronous iterator; under ASGI Django says so once per file. Harmless here.
warnings.filterwarnings("ignore", message="StreamingHttpResponse must consume synchronous iterators")
WHITENOISE_USE_FINDERS = True  # serve static/ straight from the apps: no collectstatic step to forget

LOGGING = {
    "version": 1,
    "disable_existing_loggers": False,
    "formatters": {"short": {"format": "%(asctime)s %(levelname)s %(name)s: %(message)s"}},
    "handlers": {"console": {"class": "logging.StreamHandler", "formatter": "short"}},
    "root": {"handlers": ["console"], "level": "WARNING"},
    "loggers": {name: {"level": "INFO"} for name in ("fleet", "robots", "interpreter", "simworker")},
}

# The fleet's own knobs.
FLEET_WORLD = os.environ.get("FLEET_WORLD", "paper")
# The demo world's Table 12 slots are loaded disabled unless this is set, so that a person's instruction is not
# refused because `make run` happened to start inside a slot; enable them in the admin or with this variable.
FLEET_DEMO_SCHEDULES = env_bool("FLEET_DEMO_SCHEDULES", default=False)
FLEET_ADMIN_PASSWORD = env_str("FLEET_ADMIN_PASSWORD", min_length=8)
FLEET_CONTROL_LEASE_SECONDS = 300
FLEET_IDLE_TIMEOUT_SECONDS = 600
# Execution (issue 6): where instructions run (celery workers, or "thread" in-process for tests), an optional
# queue override, and the Redis key prefix of robot locks and flags (distinct per test run).
FLEET_EXECUTE = os.environ.get("FLEET_EXECUTE", "celery")
FLEET_EXECUTE_QUEUE = os.environ.get("FLEET_EXECUTE_QUEUE", "")
FLEET_EXEC_KEY_PREFIX = os.environ.get("FLEET_EXEC_KEY_PREFIX", "fleet:exec")
