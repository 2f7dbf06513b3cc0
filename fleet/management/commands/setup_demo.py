"""Make a fresh database ready to try: roles, the demo admin, the demo world's map and locations."""

import secrets

from django.conf import settings
from django.contrib.auth.models import Group, User
from django.core.management.base import BaseCommand, CommandError

from access.roles import ADMIN, sync_groups
from fleetcore.world import WorldFormatError
from places.worlds import load_world_into_db


class Command(BaseCommand):
    help = "Create the role groups, the demo admin and load the demo world (idempotent)."

    def add_arguments(self, parser):
        parser.add_argument("--world", default=settings.FLEET_WORLD)

    def handle(self, *args, world, **options):
        sync_groups()
        password = self.ensure_admin()
        try:
            summary = load_world_into_db(world)
        except WorldFormatError as exc:
            raise CommandError(f"world {world!r} (--world or FLEET_WORLD): {exc}") from exc
        self.stdout.write(f"demo world {world!r}: {summary}")
        self.stdout.write(self.style.SUCCESS(f"login: admin / {password}"))

    def ensure_admin(self) -> str:
        """The demo admin: FLEET_ADMIN_PASSWORD, else a password generated once into var/admin_password."""
        password_file = settings.VAR_DIR / "admin_password"
        password = settings.FLEET_ADMIN_PASSWORD
        if not password:
            if not password_file.exists():
                password_file.write_text(secrets.token_urlsafe(12))
                password_file.chmod(0o600)
            password = password_file.read_text().strip()
        user, created = User.objects.get_or_create(
            username="admin", defaults={"is_staff": True, "is_superuser": True}
        )
        if created or not user.check_password(password):
            user.set_password(password)
            user.is_staff = user.is_superuser = True
            user.save()
        user.groups.add(Group.objects.get(name=ADMIN))
        return password
