"""Deployment: systemd units, supervisord, the reverse proxy, and a multi-host cluster on one machine."""
