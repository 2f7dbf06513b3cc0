"""The task lists an instruction to many robots pushes: a robot's claim and its end push that robot's list only;
the instruction's last end pushes every robot's. (Every robot's list on each claim made an instruction to N robots
cost N x N lists: an executor starting 50 robots at once starved until their locks lapsed, bench.cluster.)"""

from __future__ import annotations

import pytest

import live
from execution import runner
from execution.models import Execution, Instruction
from robots.models import Robot

ROBOTS = 6


@pytest.fixture
def shares(db):
    """One instruction to ROBOTS robots, each robot's share queued."""
    robots = [
        Robot.objects.create(name=f"r{i}", endpoint="ws://127.0.0.1:1", namespace=f"/r{i}", state="ready")
        for i in range(ROBOTS)
    ]
    instruction = Instruction.objects.create(text="turn left", status=Instruction.Status.QUEUED)
    instruction.robots.set(robots)
    return [
        Execution.objects.create(instruction=instruction, robot=robot, steps=[{"action": "turn_by"}])
        for robot in robots
    ]


@pytest.fixture
def pushed(monkeypatch):
    """The robot ids whose task list was pushed, in order."""
    ids: list[int] = []
    monkeypatch.setattr(live, "queue", lambda payload: ids.append(payload["id"]))
    return ids


def test_each_claim_pushes_only_the_claiming_robots_task_list(shares, pushed):
    for execution in shares:
        assert runner.claim(execution, "token")
    assert pushed == [execution.robot_id for execution in shares]  # ROBOTS lists, not ROBOTS x ROBOTS
    assert Instruction.objects.get(pk=shares[0].instruction_id).status == "running"


def test_only_the_first_claim_of_an_instruction_updates_and_pushes_it_and_none_reads_its_row_back(
    shares, pushed, monkeypatch, django_assert_num_queries
):
    """Each robot's claim of an instruction to N robots used to update the instruction, read it and push it, and
    read its own execution back: the executor starting 50 robots queued those calls behind each other."""
    instructions = []
    monkeypatch.setattr(live, "instruction", lambda instruction: instructions.append(instruction.status))
    early = runner.next_execution(shares[-1].robot_id)  # read before any claim: its instruction still queued
    taken = []
    for number, execution in enumerate(shares[:-1]):
        taken.append(
            runner.next_execution(execution.robot_id)
        )  # as the runner reads it, just before its claim
        # the first: its row, the instruction's, the instruction read to push, its task list (robots, lists);
        # the others: their row and their task list (the robot read with the execution)
        with django_assert_num_queries(5 if number == 0 else 2):
            assert runner.claim(taken[-1], "token")
    with django_assert_num_queries(
        3
    ):  # read as queued: the instruction's conditional update, which finds none
        assert runner.claim(early, "token")
    assert instructions == ["running"]  # pushed once, by the claim that changed it
    assert pushed == [execution.robot_id for execution in shares]
    for execution in [*taken, early]:  # what the claim wrote, as the row now says
        row = Execution.objects.get(pk=execution.pk)
        assert (execution.status, execution.worker) == (row.status, row.worker) == ("running", "token")
        assert execution.dispatched_at == row.dispatched_at is not None
    assert not runner.claim(runner.next_execution(shares[0].robot_id) or taken[0], "other")  # nobody else's


def test_a_share_that_ends_pushes_its_robots_list_and_the_last_pushes_every_robots(shares, pushed):
    for execution in shares:
        runner.claim(execution, "token")
    pushed.clear()
    first, *others = shares
    assert runner.finish(first, "token", "succeeded", "turned")
    assert pushed == [first.robot_id]  # its list shows nothing running, while the others still turn
    assert Instruction.objects.get(pk=first.instruction_id).status == "running"
    pushed.clear()
    for execution in others:
        runner.finish(execution, "token", "succeeded", "turned")
    ended = [execution.robot_id for execution in others[:-1]]
    assert pushed[: len(ended)] == ended
    assert sorted(pushed[len(ended) :]) == sorted(e.robot_id for e in shares)  # settled: every robot's list
    assert Instruction.objects.get(pk=first.instruction_id).status == "succeeded"


def test_a_share_that_ends_before_the_others_reads_no_other_share_and_pushes_no_instruction(
    shares, pushed, monkeypatch
):
    """Each robot's end read every share of the instruction with its robot, to see whether it was the last: an
    instruction to 50 robots read 2,500 rows, a fifth of its executor's time."""
    from django.db import connection

    for execution in shares:
        runner.claim(execution, "token")
    instructions, rows = [], []
    monkeypatch.setattr(live, "instruction", lambda instruction: instructions.append(instruction.status))

    def counting(execute, sql, params, many, context):
        result = execute(sql, params, many, context)
        if sql.lstrip().upper().startswith("SELECT"):
            rows.append(context["cursor"].rowcount)
        return result

    with connection.execute_wrapper(counting):
        assert runner.finish(shares[0], "token", "succeeded", "turned")
    assert rows and max(rows) <= 1  # its robot, its task list, whether any share is open: never every share
    assert instructions == [] and pushed[-1] == shares[0].robot_id  # its list, not the unchanged instruction


def test_the_task_lists_of_many_robots_are_read_at_once_and_each_as_alone(
    shares, django_assert_max_num_queries
):
    """An instruction to 50 robots pushes 50 task lists: one query for all of them, not three round trips each
    (its POST took 2 to 2.7 s on the cluster); each list is the one the robot's own page reads."""
    from execution import queues

    runner.claim(shares[0], "token")  # one robot running its share, the others waiting
    robots = [execution.robot for execution in shares]
    with django_assert_max_num_queries(1):
        together = queues.robot_queues(robots)
    assert together == [queues.robot_queue(robot) for robot in robots]
    assert together[0]["running"]["instruction"] == shares[0].instruction_id
    assert [len(q["queued"]) for q in together] == [0] + [1] * (ROBOTS - 1)


@pytest.fixture
def share_alone(transactional_db, exec_settings):
    """One robot with no bindings (it cannot be linked) and its queued share of an instruction, committed (the
    blocking pool's threads read it on connections of their own)."""
    robot = Robot.objects.create(name="r0", endpoint="ws://127.0.0.1:1", namespace="/r0", state="ready")
    instruction = Instruction.objects.create(text="turn r0 left", status=Instruction.Status.QUEUED)
    return Execution.objects.create(instruction=instruction, robot=robot, steps=[{"action": "turn_by"}])


def _run(execution: Execution):
    """run_execution on a loop of its own, its blocking pool closed after (a lease no step reaches)."""
    import asyncio
    from types import SimpleNamespace

    from execution import blocking

    taken = runner.next_execution(execution.robot_id)  # as the drain reads it

    async def body():
        try:
            return await runner.run_execution(
                taken, SimpleNamespace(token="t", beat=lambda lively=None: None)
            )
        finally:
            await blocking.close()

    return asyncio.run(body())


def test_a_robot_whose_link_cannot_be_made_fails_its_claimed_run_saying_why(share_alone):
    """The claim and the link are one call to the pool: the link's failure comes after the claim, and the run
    ends failed with it (never left running for the watchdog)."""
    assert _run(share_alone) is None
    row = Execution.objects.get(pk=share_alone.pk)
    assert row.status == "failed" and "r0: no move topic is bound" in row.error


def test_a_database_gone_before_the_claim_leaves_the_share_queued_for_the_sweep(share_alone, monkeypatch):
    from django.db import OperationalError

    def gone(*_args):
        raise OperationalError("the database system is shutting down")

    monkeypatch.setattr(runner, "claim", gone)
    with pytest.raises(OperationalError):
        _run(share_alone)
    assert Execution.objects.get(pk=share_alone.pk).status == "queued"  # not failed, not "unrecorded"
