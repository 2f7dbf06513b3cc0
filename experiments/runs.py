"""The experiments page's runs: response time and success rate against any registered robots (real ones too).

A run is an ExperimentRun row; the Celery task takes its primary key and delegates to `execute`, which reuses the
bench's trial code (bench/response.py) over each robot's bound move and odometry topics.
"""

import asyncio
import time

from asgiref.sync import sync_to_async
from celery import shared_task
from django.db import models, transaction
from django.utils import timezone

from execution.instructions import submit
from execution.models import Instruction
from experiments import paper
from experiments.drivers import DirectDriver
from experiments.models import ExperimentRun
from experiments.probe import RobotLink, watch_odometry
from experiments.response import speed_grid
from robots.rosbridge import RosbridgeClient

KINDS = ("response", "success")
MAX_TRIALS = 50
CELLS = [
    (u, w) for u in paper.LINEAR_SPEEDS for w in paper.ANGULAR_SPEEDS
]  # a response run's grid, per robot


class ExperimentError(ValueError):
    """A run that cannot start; the message says why, in words."""


class _NoReception:
    """Real robots have no simulator hook: "received at the endpoint" is not measured."""

    def first_after(self, *_args, **_kwargs):
        return None


def start_run(kind: str, robots, user, params: dict, confirmed: bool) -> ExperimentRun:
    """Validate, store and queue a run; moving robots needs an explicit confirmation."""
    if kind not in KINDS:
        raise ExperimentError(f"kind: expected one of {', '.join(KINDS)}, got {kind!r}")
    robots = list(robots)
    if not robots:
        raise ExperimentError("robots: choose at least one robot")
    if not confirmed:
        raise ExperimentError("confirm: the robots will move; tick the confirmation to run")
    trials = params.get("trials", 3)
    if not isinstance(trials, int) or not 1 <= trials <= MAX_TRIALS:
        raise ExperimentError(f"trials: a whole number from 1 to {MAX_TRIALS}")
    total = len(robots) * (trials * len(CELLS) if kind == "response" else trials)
    run = ExperimentRun.objects.create(kind=kind, user=user, params={**params, "trials": trials}, total=total)
    run.robots.set(robots)
    transaction.on_commit(lambda: run_experiment.delay(run.pk))
    return run


@shared_task(name="experiments.runs.run_experiment", acks_late=True)
def run_experiment(run_pk: int) -> str:
    """Run one stored experiment (idempotent: a finished run is not run again)."""
    claimed = ExperimentRun.objects.filter(pk=run_pk, status="queued").update(
        status="running", started_at=timezone.now()
    )
    if not claimed:
        return "already taken"
    run = ExperimentRun.objects.get(pk=run_pk)
    try:
        run.results = execute(run)
        run.status = "succeeded"
    except Exception as exc:  # stored on the run for the page to show
        run.results = {**(run.results or {}), "error": f"{type(exc).__name__}: {exc}"}
        run.status = "failed"
    run.finished_at = timezone.now()
    run.save(update_fields=["results", "status", "finished_at"])
    return run.status


def execute(run: ExperimentRun) -> dict:
    robots = list(run.robots.prefetch_related("bindings"))
    if run.kind == "response":
        return asyncio.run(_response(robots, run.params, Progress(run.pk, per_step=run.params["trials"])))
    return _success(robots, run.user, run.params, Progress(run.pk))


class Progress:
    """Counts a run's steps done into its row, which the page polls: `step()` in sync code, `await astep()` in
    an event loop."""

    def __init__(self, run_pk: int, per_step: int = 1):
        self.run_pk, self.per_step = run_pk, per_step

    def step(self) -> None:
        ExperimentRun.objects.filter(pk=self.run_pk).update(done=models.F("done") + self.per_step)

    async def astep(self) -> None:
        await sync_to_async(self.step, thread_sensitive=False)()


def robot_link(robot):
    """A bench RobotLink from a registered robot's move and odometry bindings."""
    bound = {b.action: b.target for b in robot.bindings.all() if b.target}
    missing = [a for a in ("move", "odometry") if a not in bound]
    if missing:
        raise ExperimentError(f"{robot.name}: no {' and no '.join(missing)} binding; register it first")
    return RobotLink(
        robot.name, bound["move"], bound["odometry"], robot.max_linear, robot.max_angular, url=robot.endpoint
    )


async def _response(robots, params: dict, progress) -> dict:
    """Start/stop response over the paper's speed grid (capped by each robot's limits), robot by robot."""
    links = [robot_link(r) for r in robots]
    clients = {}
    out = {}
    try:
        for link in links:
            if link.url not in clients:
                clients[link.url] = RosbridgeClient(link.url, ping_interval=None)
                await clients[link.url].connect()
            watches = {link.name: await watch_odometry(clients[link.url], link)}
            grid = await speed_grid(
                DirectDriver(clients),
                link,
                watches,
                _NoReception(),
                params["trials"],
                float(params.get("hold_s", 1.0)),
                table=5,
                on_cell=progress.astep,
            )
            out[link.name] = {k: grid[k] for k in ("cells", "cap", "start_s", "stop_s")}
    finally:
        for client in clients.values():
            await client.close()
    return {"robots": out}


def _success(robots, user, params: dict, progress) -> dict:
    """Type IV instructions ("shift R to G") to each robot's goal; the share that succeeded."""
    goal = params.get("goal", "A")
    out = {}
    for robot in robots:
        ok = 0
        for _ in range(params["trials"]):
            instruction = submit(f"shift {robot.name} to {goal}", user, source="experiment")
            deadline = time.time() + float(params.get("timeout_s", 120))
            while time.time() < deadline:
                instruction.refresh_from_db()
                if instruction.is_final or instruction.status == Instruction.Status.NEEDS_USER:
                    break
                time.sleep(0.2)
            ok += instruction.status == Instruction.Status.SUCCEEDED
            progress.step()
        out[robot.name] = {"trials": params["trials"], "succeeded": ok, "rate": ok / params["trials"]}
    return {"goal": goal, "robots": out}
