"""The paper's tables as transcribed: the printed shapes and a few printed values."""

import pytest

from experiments import paper

SHAPES = {3: (8, 3), 4: (8, 3), 5: (8, 3), 6: (6, 3), 7: (3, 3), 8: (3, 3), 13: (3, 4), 14: (3, 4)}


@pytest.mark.parametrize(("number", "shape"), SHAPES.items())
def test_table_has_the_printed_rows_and_columns(number, shape):
    table = paper.TABLES[number]
    assert table.shape() == shape
    for section in table.sections:
        for row in section.rows:
            assert len(row.values) == len(table.columns)


def test_every_table_of_section_4_is_there():
    assert sorted(paper.TABLES) == [3, 4, 5, 6, 7, 8, 13, 14]


def test_start_and_stop_grids_have_two_sections_of_four_angular_speeds():
    for number in (3, 4, 5):
        sections = paper.TABLES[number].sections
        assert [s.name for s in sections] == ["StartResponse (s)", "StopResponse (s)"]
        assert [r.param for r in sections[0].rows] == [0.0, 0.5, 1.0, 1.5]


def test_printed_values_are_where_the_paper_puts_them():
    assert paper.TABLE_3.value("StartResponse (s)", "ω_z^s = 0.0 rad/s", 0) == 0.871
    assert paper.TABLE_5.value("StopResponse (s)", "ω_z^e = 0.0 rad/s", 2) == 2.552
    assert paper.TABLE_6.value("StopResponse (s)", "TwoRobots", 2) == 2.987
    assert paper.TABLE_8.value("Average competition time (s)", "FourRobots", 2) == 4.62
    assert paper.TABLE_14.value("Goal with navigation", "TiaGo", 3) == 0.75


def test_table_6_single_robot_rows_repeat_table_5_first_rows():
    five, six = paper.TABLE_5, paper.TABLE_6
    assert six.sections[0].rows[0].values == five.sections[0].rows[0].values
    assert six.sections[1].rows[0].values == five.sections[1].rows[0].values


def test_success_rates_are_fractions_of_twenty_trials():
    for number in (13, 14):
        for row in paper.TABLES[number].sections[0].rows:
            assert all(0 <= v <= 1 and round(v * 20, 6).is_integer() for v in row.values)


def test_unknown_section_is_a_clear_error():
    with pytest.raises(KeyError, match="no section"):
        paper.TABLE_3.value("Nope", "x", 0)
