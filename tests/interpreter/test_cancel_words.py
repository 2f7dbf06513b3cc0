"""'cancel #12' and 'cancel husky's instruction': the cancel action's words, read by the parser (no Django)."""

from interpreter.parser import interpret


def test_cancel_with_a_number_names_that_instruction(grammar):
    for text in ("cancel #12", "cancel instruction 12", "abort number 12"):
        result = interpret(text, grammar).to_dict()
        assert result["valid"], (text, result["reason"])
        assert [(s["action"], s.get("instruction")) for s in result["steps"]] == [("cancel", 12)]
        assert result["read_back"] == ["cancel #12"]


def test_cancel_a_robots_instruction_names_the_robot(grammar):
    for text in ("cancel husky's instruction", "cancel husky’s instruction", "call off husky"):
        result = interpret(text, grammar).to_dict()
        assert result["valid"], (text, result["reason"])
        step = result["steps"][0]
        assert (step["action"], step["robots"], step.get("instruction")) == ("cancel", ["husky"], None)


def test_a_possessive_of_no_robot_is_not_a_robot(grammar):
    result = interpret("cancel nobody's instruction", grammar).to_dict()
    assert not result["valid"]
