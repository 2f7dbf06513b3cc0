"""`python manage.py instruct --user NAME [--wait] "TEXT"`: submit an instruction as a user, optionally follow it.

With --wait, prints each state transition of the instruction's robots with its timestamp, then the outcome
and the timings; exits 0 only when the instruction succeeded.

A plain stop ("stop", "stop husky") is read before the grammar is built (interpreter/quickstop.py) and its zeros
asked of the running portal's links process at once (execution.fast_stop.by_portal: links already up, as the
page's stop); without a portal, this process stops the robots on links of its own (fast_stop.stop_blocking).
Then the instruction is submitted as any other, and control.stop does the stop's bookkeeping.
"""

import time

from django.contrib.auth import get_user_model
from django.core.management.base import BaseCommand, CommandError

from access.roles import can_control
from execution import fast_stop
from execution.instructions import submit
from execution.models import Instruction
from interpreter.quickstop import stop_subject
from robots.models import StateTransition

TIMINGS = (
    "received_at",
    "interpreted_at",
    "dispatched_at",
    "first_command_at",
    "motion_started_at",
    "finished_at",
)


class Command(BaseCommand):
    help = "Submit an instruction as a user (with that user's permissions); --wait follows it to the end."

    def add_arguments(self, parser):
        parser.add_argument("text", help='the instruction, e.g. "move turtlebot to A"')
        parser.add_argument("--user", required=True, help="the user it is submitted as")
        parser.add_argument("--wait", action="store_true", help="follow the transitions until it ends")
        parser.add_argument("--timeout", type=float, default=300.0, help="seconds to wait at most")

    def handle(self, *args, text, user, wait, timeout, **options):
        self.verbosity = options.get("verbosity", 1)
        account = get_user_model().objects.filter(username=user).first()
        if account is None:
            raise CommandError(f"--user: no user named {user!r}")
        names = stop_subject(text)
        if names is not None and can_control(account):
            self.stop_first(names)
        instruction = submit(text, account, source="cli")
        self.stdout.write(f"instruction #{instruction.pk}: {instruction.status}")
        if not wait:
            return
        instruction = self.follow(instruction, timeout)
        self.report(instruction)
        if instruction.status != Instruction.Status.SUCCEEDED:
            raise CommandError(f"instruction #{instruction.pk} {instruction.status}: {instruction.outcome}")

    def stop_first(self, names) -> None:
        """The zeros before the grammar: by the running portal's links, else on this process's own."""
        asked = time.monotonic()
        answer = fast_stop.by_portal(names)
        if answer is not None and answer["zeroed"]:
            took = (time.monotonic() - asked) * 1000
            self.stdout.write(
                f"zeros sent by the portal's links in {took:.0f} ms: {', '.join(answer['zeroed'])}"
            )
            if self.verbosity > 1:  # for the bench: when the request left, on the machine's monotonic clock
                self.stdout.write(f"portal stop asked at monotonic {asked:.6f}")
        if answer is None or answer["missed"] or answer["unknown"]:
            fast_stop.stop_blocking(names)

    def follow(self, instruction: Instruction, timeout: float) -> Instruction:
        """Print transitions as they are stored, until the instruction is final or the timeout."""
        seen: set[int] = set()
        deadline = time.monotonic() + timeout
        while True:
            instruction.refresh_from_db()
            for record in (
                StateTransition.objects.filter(instruction=instruction)
                .exclude(pk__in=seen)
                .order_by("at", "pk")
                .select_related("robot")
            ):
                seen.add(record.pk)
                reason = f"  ({record.reason})" if record.reason else ""
                self.stdout.write(
                    f"{record.at:%H:%M:%S.%f}"[:-3]
                    + f"  {record.robot.name}: {record.from_state} -> {record.to_state}{reason}"
                )
            if instruction.is_final or instruction.status == Instruction.Status.NEEDS_USER:
                return instruction
            if time.monotonic() > deadline:
                raise CommandError(
                    f"instruction #{instruction.pk} still {instruction.status} after {timeout:g} s"
                )
            time.sleep(0.1)

    def report(self, instruction: Instruction) -> None:
        self.stdout.write(f"outcome: {instruction.status}: {instruction.outcome}")
        start = instruction.received_at
        for name in TIMINGS:
            at = getattr(instruction, name)
            delta = f"+{(at - start).total_seconds() * 1000:.0f} ms" if at else "-"
            self.stdout.write(f"  {name:<18} {delta}")
