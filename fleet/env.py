"""Typed settings from the environment.

Every helper raises ImproperlyConfigured naming the variable, so a bad value stops start-up with one line that
says what to fix. No Django import beyond the exception: settings.py calls these before Django is set up.
"""

import ipaddress
import os
import secrets
from pathlib import Path
from urllib.parse import urlparse

import dj_database_url
from django.core.exceptions import ImproperlyConfigured

from robots.endpoints import AllowList

TRUE_WORDS = {"1", "true", "yes", "on"}
FALSE_WORDS = {"0", "false", "no", "off", ""}


def env_bool(name: str, default: bool = False) -> bool:
    """Read a yes/no variable; anything else is an error."""
    raw = os.environ.get(name)
    if raw is None:
        return default
    word = raw.strip().lower()
    if word in TRUE_WORDS:
        return True
    if word in FALSE_WORDS:
        return False
    raise ImproperlyConfigured(f"{name}: expected one of 1/0, true/false, yes/no, on/off, got {raw!r}")


def env_int(name: str, default: int, minimum: int = 0, maximum: int = 10**9) -> int:
    """Read a whole number within [minimum, maximum]; anything else is an error."""
    raw = os.environ.get(name)
    if raw is None or raw.strip() == "":
        return default
    try:
        value = int(raw.strip())
    except ValueError:
        raise ImproperlyConfigured(f"{name}: expected a whole number, got {raw!r}") from None
    if value < minimum:
        raise ImproperlyConfigured(f"{name}: must be at least {minimum}, got {value}")
    if value > maximum:
        raise ImproperlyConfigured(f"{name}: must be at most {maximum}, got {value}")
    return value


def tls_settings(behind_tls: bool, hosts: list[str]) -> dict:
    """The settings FLEET_BEHIND_TLS turns on (all off on a laptop's plain http://127.0.0.1:8000).

    Behind a TLS-terminating proxy that sets X-Forwarded-Proto: https everywhere (redirect), for a year (HSTS),
    cookies only over https, and the proxy's word taken for the scheme. `manage.py check --deploy` is clean.
    """
    origins = [host for host in hosts if host not in {"*", "testserver"}]
    if not behind_tls:
        return {"CSRF_TRUSTED_ORIGINS": [f"http://{host}:8000" for host in origins]}
    return {
        "SECURE_SSL_REDIRECT": True,
        "SECURE_PROXY_SSL_HEADER": ("HTTP_X_FORWARDED_PROTO", "https"),
        "SECURE_HSTS_SECONDS": 365 * 24 * 3600,
        "SECURE_HSTS_INCLUDE_SUBDOMAINS": True,
        "SECURE_HSTS_PRELOAD": True,
        "SESSION_COOKIE_SECURE": True,
        "CSRF_COOKIE_SECURE": True,
        "CSRF_TRUSTED_ORIGINS": [f"https://{host}" for host in origins],
    }


def env_list(name: str, default: list[str]) -> list[str]:
    """Read a comma-separated list; empty items are an error."""
    raw = os.environ.get(name)
    if raw is None:
        return default
    items = [item.strip() for item in raw.split(",")]
    if not all(items):
        raise ImproperlyConfigured(
            f"{name}: expected a comma-separated list without empty items, got {raw!r}"
        )
    return items


def env_database(name: str, default_sqlite: Path) -> dict:
    """Turn DATABASE_URL into Django's DATABASES['default'] (SQLite file when unset)."""
    raw = os.environ.get(name)
    if not raw:
        # IMMEDIATE: several robots' runners write at once; a deferred transaction that later upgrades its
        # lock fails at once with "database is locked" instead of waiting for the timeout.
        # The tests' database is a file too: Django's default in-memory one shares a cache between threads,
        # where a write meeting another thread's fails at once ("table is locked") instead of waiting.
        return {
            "ENGINE": "django.db.backends.sqlite3",
            "NAME": str(default_sqlite),
            "OPTIONS": {"timeout": 20, "transaction_mode": "IMMEDIATE"},
            "TEST": {"NAME": str(default_sqlite.with_name(f"test_{default_sqlite.name}"))},
        }
    scheme = urlparse(raw).scheme
    if scheme not in {"sqlite", "postgres", "postgresql", "pgsql", "postgis"}:
        raise ImproperlyConfigured(
            f"{name}: unsupported scheme {scheme!r}; use postgres://… or sqlite:///path"
        )
    try:
        config = dj_database_url.parse(raw, conn_max_age=60, conn_health_checks=True)
    except Exception as exc:  # dj_database_url raises several types for malformed URLs
        raise ImproperlyConfigured(f"{name}: cannot parse {raw!r}: {exc}") from None
    if not config.get("NAME"):
        raise ImproperlyConfigured(f"{name}: no database name in {raw!r}")
    return config


def env_redis_url(name: str, default_socket: Path) -> str:
    """Read REDIS_URL: redis://, rediss:// or unix:// (the embedded Redis is a unix socket under var/)."""
    raw = os.environ.get(name) or f"unix://{default_socket}"
    parsed = urlparse(raw)
    if parsed.scheme not in {"redis", "rediss", "unix"}:
        raise ImproperlyConfigured(
            f"{name}: expected redis://host:port/db, rediss://… or unix:///path, got {raw!r}"
        )
    if parsed.scheme == "unix" and not parsed.path:
        raise ImproperlyConfigured(f"{name}: unix:// URL without a socket path: {raw!r}")
    if parsed.scheme != "unix":
        try:
            parsed.port  # noqa: B018 - raises ValueError on a bad port
        except ValueError:
            raise ImproperlyConfigured(f"{name}: bad port in {raw!r}") from None
        if not parsed.hostname:
            raise ImproperlyConfigured(f"{name}: no host in {raw!r}")
    return raw


def celery_broker_url(redis_url: str) -> str:
    """Celery spells a unix-socket Redis as redis+socket://."""
    parsed = urlparse(redis_url)
    if parsed.scheme == "unix":
        return f"redis+socket://{parsed.path}"
    return redis_url


CHANNELS_SOCKET_TIMEOUT = 30  # s: a channel-layer command (a PUBLISH) that gets no answer fails after this


def channels_host(redis_url: str) -> dict:
    """channels-redis takes redis:// and unix:// URLs as they are, with redis-py's options beside them (its list
    layer's 5 s blocking receive once met redis-py 8's default 5 s socket timeout: idle consumers crashed)."""
    return {"address": redis_url, "socket_timeout": CHANNELS_SOCKET_TIMEOUT}


def env_secret_key(name: str, key_file: Path) -> str:
    """Read SECRET_KEY, else the one generated once into var/ (never committed)."""
    raw = os.environ.get(name)
    if raw is not None:
        if len(raw) < 32:
            raise ImproperlyConfigured(f"{name}: must be at least 32 characters long")
        return raw
    if key_file.exists():
        return key_file.read_text().strip()
    key_file.parent.mkdir(parents=True, exist_ok=True)
    key = secrets.token_urlsafe(50)
    key_file.write_text(key)
    key_file.chmod(0o600)
    return key


def env_str(name: str, default: str | None = None, min_length: int = 0) -> str | None:
    """Read a string variable that, when set, must be at least min_length long."""
    raw = os.environ.get(name)
    if raw is None or raw == "":
        return default
    if len(raw) < min_length:
        raise ImproperlyConfigured(f"{name}: must be at least {min_length} characters long")
    return raw


def env_networks(name: str, default: list[str]) -> list[str]:
    """Read a comma-separated allow-list of networks (CIDRs), addresses and host names."""
    entries = env_list(name, default)
    try:
        AllowList.parse(entries)
    except ValueError as exc:
        raise ImproperlyConfigured(f"{name}: {exc}") from None
    return entries


def env_addresses(name: str, default: list[str]) -> list[str]:
    """Read a comma-separated list of addresses and CIDRs (no host names: a proxy is trusted by its address)."""
    entries = env_list(name, default) if os.environ.get(name, "").strip() else default
    for entry in entries:
        try:
            ipaddress.ip_network(entry, strict=False)
        except ValueError:
            raise ImproperlyConfigured(
                f"{name}: {entry!r} is neither an address nor a network (CIDR)"
            ) from None
    return entries
