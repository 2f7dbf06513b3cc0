"""Settings for the fleet portal, all from the environment through fleet/env.py.

Defaults work on a laptop with nothing installed: a SQLite file and an embedded Redis, both under var/.
"""

import os
import warnings
from pathlib import Path

from fleet.env import (
    celery_broker_url,
    channels_host,
    env_addresses,
    env_bool,
    env_database,
    env_int,
    env_list,
    env_networks,
    env_redis_url,
    env_secret_key,
    env_str,
    tls_settings,
)

BASE_DIR = Path(__file__).resolve().parent.parent
VAR_DIR = Path(os.environ.get("FLEET_VAR_DIR", BASE_DIR / "var"))
VAR_DIR.mkdir(parents=True, exist_ok=True)

SECRET_KEY = env_secret_key("SECRET_KEY", VAR_DIR / "secret_key")
DEBUG = env_bool("FLEET_DEBUG", default=False)
ALLOWED_HOSTS = env_list("ALLOWED_HOSTS", ["127.0.0.1", "localhost", "[::1]", "testserver"])

REDIS_URL = env_redis_url("REDIS_URL", VAR_DIR / "redis.sock")
EMBEDDED_REDIS = "REDIS_URL" not in os.environ or not os.environ["REDIS_URL"]

# Project and domain apps, from the top layer down (docs/ARCHITECTURE.md; `make lint` checks the order).
FLEET_APPS = [
    "fleet",
    "portal",
    "experiments",
    "recordings",
    "execution",
    "interpreter",
    "access",
    "places",
    "robots",
    "alerts",
    "audit",
    "simworker",
]

INSTALLED_APPS = [
    "django.contrib.admin",
    "django.contrib.auth",
    "django.contrib.contenttypes",
    "django.contrib.sessions",
    "django.contrib.messages",
    "django.contrib.staticfiles",
    "channels",
    "axes",
    # ninja as an app serves Swagger UI from its own static files (ninja/static/ninja/), not from a CDN
    "ninja",
    *FLEET_APPS,
]

MIDDLEWARE = [
    "django.middleware.security.SecurityMiddleware",  # nosniff, Referrer-Policy same-origin, COOP (defaults)
    "portal.middleware.ContentSecurityPolicy",
    "whitenoise.middleware.WhiteNoiseMiddleware",
    "django.contrib.sessions.middleware.SessionMiddleware",
    "django.middleware.common.CommonMiddleware",
    "django.middleware.csrf.CsrfViewMiddleware",
    "django.contrib.auth.middleware.AuthenticationMiddleware",
    "portal.middleware.LoginRequired",
    "django.contrib.messages.middleware.MessageMiddleware",
    "django.middleware.clickjacking.XFrameOptionsMiddleware",
    "axes.middleware.AxesMiddleware",  # last, as django-axes asks: turns a lockout into its 429 answer
    "portal.middleware.StoreRefusals",  # Redis or the database refusing: 503 with the reason, not a bare 500
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
                "access.roles.context_processor",
            ],
        },
    },
]

DATABASES = {"default": env_database("DATABASE_URL", VAR_DIR / "fleet.sqlite3")}
DEFAULT_AUTO_FIELD = "django.db.models.BigAutoField"

CACHES = {
    "default": {
        "BACKEND": "fleet.cache.RedisCache",  # one client per pool (fleet/cache.py)
        "LOCATION": REDIS_URL,
        "KEY_PREFIX": os.environ.get("FLEET_REDIS_PREFIX", "fleet"),
    }
}

# Redis pub/sub (channels_redis' own layer): a push is one PUBLISH and each web process's reader of a group (its one
# subscriber there: portal.fanout) gets it on its subscription, where the list-based layer cost the sender about
# seven round trips and a Lua script, and every reader three or four more per push (docs/scale.md, eighth session:
# the web hosts 0.77x the CPU at 100 robots). A push is not kept for a reader that is not subscribed at that moment:
# nothing is queued in Redis for a web process that is away, as the pages hold their state from a snapshot anyway.
CHANNEL_LAYERS = {
    "default": {
        "BACKEND": "fleet.channel_layer.RedisPubSubChannelLayer",  # subscriptions that survive a cut
        "CONFIG": {
            "hosts": [channels_host(REDIS_URL)],
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
CELERY_IMPORTS = ["experiments.runs"]  # tasks outside the apps' tasks.py modules
CELERY_TASK_ROUTES = {
    "robots.tasks.*": {"queue": "registration"},
    "simworker.tasks.*": {"queue": "sim"},
    "execution.tasks.stop_*": {"queue": "control"},
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

# make test (fleet/testrun.py) sets FLEET_FAST_PASSWORD_HASH for itself and the servers its tests start: a
# test suite logs hundreds of users in, and PBKDF2's 1,000,000 rounds per login were its largest CPU cost. Never
# set it for a portal that people use.
if env_bool("FLEET_FAST_PASSWORD_HASH", default=False):
    PASSWORD_HASHERS = ["django.contrib.auth.hashers.MD5PasswordHasher"]

AUTH_PASSWORD_VALIDATORS = [
    {"NAME": "django.contrib.auth.password_validation.MinimumLengthValidator", "OPTIONS": {"min_length": 8}},
]
# --- security (issue 15; docs/security.md) ------------------------------------------------------------------
# One switch for deployments behind a TLS-terminating proxy: HSTS, secure cookies, SSL redirect, proxy header.
FLEET_BEHIND_TLS = env_bool("FLEET_BEHIND_TLS", default=False)
globals().update(
    tls_settings(FLEET_BEHIND_TLS, ALLOWED_HOSTS)
)  # CSRF_TRUSTED_ORIGINS, SECURE_*, *_COOKIE_SECURE
# Sessions end after a working day, however active (FLEET_SESSION_HOURS); the cookie is never readable by JS.
SESSION_COOKIE_AGE = env_int("FLEET_SESSION_HOURS", 12, minimum=1, maximum=24 * 30) * 3600
SESSION_COOKIE_HTTPONLY = True
SESSION_COOKIE_SAMESITE = CSRF_COOKIE_SAMESITE = "Lax"
# Login throttling (django-axes): 5 wrong passwords for one username (from any address), or from one address (for
# any usernames), lock that username, or that address, out (429) for 15 minutes; a success resets the count. So a
# guesser can neither spread one account's guesses over addresses nor one address's over accounts; the price is
# that a guesser can lock an account out for the cool-off (`manage.py axes_reset_username` lifts it). Works for the
# login page and the admin's alike (both go through the authentication backends).
AUTHENTICATION_BACKENDS = ["axes.backends.AxesStandaloneBackend", "django.contrib.auth.backends.ModelBackend"]
AXES_FAILURE_LIMIT = env_int("FLEET_LOGIN_ATTEMPTS", 5, minimum=1, maximum=100)
AXES_COOLOFF_TIME = 0.25  # hours
AXES_LOCKOUT_PARAMETERS = ["username", "ip_address"]  # either one past the limit locks
AXES_RESET_ON_SUCCESS = True
# The client's address: REMOTE_ADDR, or X-Forwarded-For only when the peer is one of these proxies (addresses or
# CIDRs; default none). Behind the reference nginx, its address (deploy/nginx/fleet.conf). portal/clientaddr.py.
FLEET_TRUSTED_PROXIES = env_addresses("FLEET_TRUSTED_PROXIES", [])
AXES_CLIENT_IP_CALLABLE = "portal.clientaddr.client_address"
AXES_VERBOSE = False
# Content-Security-Policy on every answer (portal.middleware.ContentSecurityPolicy; Django 6 reads the same
# setting): our own scripts, styles and sockets only; no inline script or style (data for a page goes in
# json_script blocks, which never run); camera frames and the favicon are data: URLs; no page may be framed.
SECURE_CSP = {
    "default-src": ["'self'"],
    "script-src": ["'self'"],
    "style-src": ["'self'"],
    "img-src": ["'self'", "data:"],
    "connect-src": ["'self'"],
    "object-src": ["'none'"],
    "base-uri": ["'none'"],
    "form-action": ["'self'"],
    "frame-ancestors": ["'none'"],
}
# --- end of security ---------------------------------------------------------------------------------------

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
    "filters": {"one_line": {"()": "fleet.logfilters.OneLine"}},
    "root": {"handlers": ["console"], "level": "WARNING"},
    "loggers": {
        **{name: {"level": "INFO"} for name in FLEET_APPS},
        "django.request": {
            "filters": ["one_line"]
        },  # a refused request (403): one line; a 500 keeps its traceback
    },
}

# The fleet's own knobs.
FLEET_WORLD = os.environ.get("FLEET_WORLD", "paper")
# The simulated endpoints' first port (as `make run` starts them): the registration page's prefill.
FLEET_SIM_PORT_BASE = env_int("FLEET_SIM_PORT_BASE", 9090, minimum=1, maximum=65535)
# The demo world's Table 12 slots are loaded disabled unless this is set, so that a person's instruction is not
# refused because `make run` happened to start inside a slot; enable them in the admin or with this variable.
FLEET_DEMO_SCHEDULES = env_bool("FLEET_DEMO_SCHEDULES", default=False)
FLEET_ADMIN_PASSWORD = env_str("FLEET_ADMIN_PASSWORD", min_length=8)
FLEET_CONTROL_LEASE_SECONDS = 300
FLEET_IDLE_TIMEOUT_SECONDS = 600
# A question of the interpreter's nobody answers expires after this long (execution/sweeps.py): cancelled with a
# note ("expired: no answer within 10 min"), its robots back to ready, gone from the console's Progress.
FLEET_QUESTION_EXPIRY_SECONDS = env_int("FLEET_QUESTION_EXPIRY_SECONDS", 600, minimum=10)
# Execution (issue 6): the Redis key prefix of robot locks, flags and executor membership (distinct per test run).
FLEET_EXEC_KEY_PREFIX = os.environ.get("FLEET_EXEC_KEY_PREFIX", "fleet:exec")
# The links process's stop socket (robots/stopsocket.py): a fresh CLI's stop is zeroed there, on links kept up.
FLEET_STOP_SOCKET = VAR_DIR / "proc" / "stop.sock"

# ----- Robots are untrusted input (issue 15; robots/limits.py, robots/endpoints.py) -----
# Caps on what one rosbridge endpoint may send: a WebSocket frame (and a reassembled fragmented message), the
# names one rosapi list may hold (topics, nodes, services, params), and one robot_description. Each refusal names
# its variable. Registration connects only to hosts in FLEET_ROBOT_ALLOWED_NETWORKS (CIDRs, addresses or host
# names; default loopback and the private ranges).
FLEET_ROBOT_MAX_FRAME_MB = env_int("FLEET_ROBOT_MAX_FRAME_MB", 16, minimum=1)
FLEET_ROBOT_MAX_TOPICS = env_int("FLEET_ROBOT_MAX_TOPICS", 100_000, minimum=1)
FLEET_ROBOT_MAX_URDF_MB = env_int("FLEET_ROBOT_MAX_URDF_MB", 4, minimum=1)
# inbound frames per endpoint link and second beyond twice what its throttled subscriptions ask for; beyond that
# they are dropped, counted, the robot flagged, an alert raised (robots/rosbridge/inflow.py)
FLEET_ROBOT_MAX_FRAMES_PER_S = env_int("FLEET_ROBOT_MAX_FRAMES_PER_S", 2000, minimum=10)
# a whole endpoint's discovery (an endpoint with hundreds of namespaced robots takes longer than the default)
FLEET_DISCOVERY_TIMEOUT_S = env_int("FLEET_DISCOVERY_TIMEOUT_S", 15, minimum=1, maximum=3600)
FLEET_ROBOT_ALLOWED_NETWORKS = env_networks(
    "FLEET_ROBOT_ALLOWED_NETWORKS",
    ["127.0.0.0/8", "::1/128", "10.0.0.0/8", "172.16.0.0/12", "192.168.0.0/16", "fc00::/7"],
)
