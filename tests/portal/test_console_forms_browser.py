"""The console in a real browser (issue 17): typed text goes with the robots ticked in the table, and the answer box
of a question shows an example that fits that question."""

import pytest

from execution import dispatch
from execution.models import Instruction

pytestmark = [pytest.mark.browser, pytest.mark.timeout(90), pytest.mark.usefixtures("seeded_ontology")]


@pytest.fixture
def no_runner(monkeypatch):
    """Instructions are stored and dispatched; nothing starts running them."""
    monkeypatch.setattr(dispatch.executor, "wake", lambda robot_ids: None)


def type_instruction(page, text):
    page.locator("#instruction").fill(text)
    page.locator("#instruction").press("Enter")


def test_typed_text_naming_no_robot_goes_to_the_ticked_robots(login, operator, fleet, no_runner):
    page = login(operator)
    page.wait_for_selector("#conn[data-state=live]")
    turtlebot = fleet["turtlebot"]
    page.locator(f"#robot-table tr[data-robot-id='{turtlebot.pk}'] input.pick").check()
    type_instruction(page, "wait 3 seconds")
    page.wait_for_function("() => document.querySelector('#progress li') !== null")
    instruction = Instruction.objects.get(text="wait 3 seconds")
    assert list(instruction.robots.values_list("name", flat=True)) == ["turtlebot"]
    assert instruction.executions.get().steps[0]["amount"] == 3.0
    line = page.locator(".steps li").first.text_content()  # the ticked robot, not "the portal chooses"
    assert line.startswith("wait turtlebot") and "chooses" not in line, line
    danger, badge = page.evaluate(
        """() => {
        const probe = document.createElement("span");
        probe.style.background = "var(--danger)";
        document.body.append(probe);
        const danger = getComputedStyle(probe).backgroundColor;
        probe.remove();
        return [danger, getComputedStyle(document.querySelector("#progress .badge")).backgroundColor];
    }"""
    )
    assert (
        badge != danger
    )  # a status badge is not painted as the top bar's alert count (it once was, all red)


@pytest.mark.parametrize(
    ("text", "example"),
    [
        ("move turtlebot forward", "e.g. move turtlebot 1 meter forward"),
        ("zoom turtlebot to B", "e.g. zoom means move"),
    ],
)
def test_the_answer_box_example_fits_the_question(login, operator, fleet, no_runner, text, example):
    page = login(operator)
    page.wait_for_selector("#conn[data-state=live]")
    type_instruction(page, text)
    answer = page.locator("input.answer")
    answer.wait_for()
    assert answer.get_attribute("placeholder") == example


def test_the_parse_line_of_a_step_naming_no_robot_says_the_portal_chooses_and_the_answer_whom(
    login, operator, fleet, no_runner
):
    """Not "rotate any" (issue 31): the parse line says the portal chooses, the answer whom and why."""
    from execution.models import TimeSlot
    from robots.models import Binding

    Binding.objects.filter(robot=fleet["turtlebot"], action="odometry").update(
        target="/odom", needs_user=False
    )
    TimeSlot.objects.all().delete()  # the turtlebot is free and can do it: it is chosen
    page = login(operator)
    page.wait_for_selector("#conn[data-state=live]")
    type_instruction(page, "spin around")
    page.wait_for_function("() => document.querySelector('#progress li') !== null")
    line = page.locator(".steps li").first.text_content()
    assert line.startswith("rotate a robot the portal chooses") and " any " not in line
    assert list(Instruction.objects.get(text="spin around").robots.values_list("name", flat=True)) == [
        "turtlebot"
    ]
    answer = page.locator("#progress li").first.text_content()
    assert "turtlebot chosen (no robot named): the only free robot that can do it" in answer
