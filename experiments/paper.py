"""The paper's numbers (Section 4, Tables 3-8, 13 and 14), transcribed as printed, with their units.

Source: the paper (Rajapaksha & Jayasundara) (the text extraction flattens the tables; the rows and columns below are the
printed ones). Two remarks on the printed units, kept as printed and corrected alongside:
- Tables 1 and 3-6 print angular speeds in "ms^-1"; an angular speed is in rad/s, which is what we command.
- Table 3-5 stop rows are labelled with the stop-time angular speed ω_z^e (Table 1), same grid as the start rows.
- Table 14's extracted header lost the end of each slot ("08.00-" ...); the slots are those of Table 13 (the text
  says 8.00-10.00, 10.00-12.00, 12.00-2.00 and 2.00-4.00).
- Table 7 is titled "single instruction" but its columns name one, two and three target locations, as printed.
"""

from dataclasses import dataclass, field


@dataclass(frozen=True)
class Row:
    label: str
    values: tuple[float, ...]
    param: float | str | None = None  # the row's swept quantity (e.g. ω = 0.5 rad/s, 2 robots)


@dataclass(frozen=True)
class Section:
    name: str
    rows: tuple[Row, ...]


@dataclass(frozen=True)
class PaperTable:
    number: int
    title: str
    unit: str
    columns: tuple[str, ...]
    sections: tuple[Section, ...]
    column_params: tuple[float | str, ...] = ()
    row_quantity: str = ""
    column_quantity: str = ""
    notes: tuple[str, ...] = field(default_factory=tuple)

    def shape(self) -> tuple[int, int]:
        """(data rows over all sections, columns)."""
        return sum(len(s.rows) for s in self.sections), len(self.columns)

    def value(self, section: str, row: str, column: int) -> float:
        """One printed value by section name, row label and column index."""
        for sec in self.sections:
            if sec.name == section:
                return next(r.values[column] for r in sec.rows if r.label == row)
        raise KeyError(f"table {self.number}: no section {section!r}")


LINEAR_SPEEDS = (0.5, 1.0, 1.5)  # m/s, the columns of Tables 3-6
ANGULAR_SPEEDS = (0.0, 0.5, 1.0, 1.5)  # rad/s (printed "ms^-1"), the rows of Tables 3-5
SPEED_COLUMNS = tuple(f"U_x^s = {u} m/s" for u in LINEAR_SPEEDS)
ANGULAR_NOTE = "angular speeds printed in ms^-1; they are rad/s"


def _grid(start: list[list[float]], stop: list[list[float]]) -> tuple[Section, ...]:
    """The Start/Stop x angular-speed grid of Tables 3-5."""
    return (
        Section(
            "StartResponse (s)",
            tuple(Row(f"ω_z^s = {w} rad/s", tuple(v), w) for w, v in zip(ANGULAR_SPEEDS, start, strict=True)),
        ),
        Section(
            "StopResponse (s)",
            tuple(Row(f"ω_z^e = {w} rad/s", tuple(v), w) for w, v in zip(ANGULAR_SPEEDS, stop, strict=True)),
        ),
    )


def _robots(start: list[list[float]] | list[float], names=("SingleRobot", "TwoRobots", "FourRobots")):
    return tuple(Row(name, tuple(v), n) for name, n, v in zip(names, (1, 2, 4), start, strict=True))


TABLE_3 = PaperTable(
    3,
    "Single robot average start/stop response time without Web interface",
    "s",
    SPEED_COLUMNS,
    _grid(
        [[0.871, 0.807, 0.787], [0.657, 0.541, 0.531], [0.561, 0.512, 0.499], [0.511, 0.501, 0.476]],
        [[1.211, 1.728, 2.161], [1.039, 1.631, 1.981], [1.001, 1.431, 1.871], [0.988, 1.181, 1.761]],
    ),
    LINEAR_SPEEDS,
    "angular speed (rad/s)",
    "linear speed (m/s)",
    (ANGULAR_NOTE,),
)
TABLE_4 = PaperTable(
    4,
    "Single robot average start/stop response time with Web interface",
    "s",
    SPEED_COLUMNS,
    _grid(
        [[0.811, 0.789, 0.766], [0.753, 0.732, 0.699], [0.611, 0.601, 0.544], [0.571, 0.577, 0.501]],
        [[1.031, 1.402, 1.981], [1.001, 1.267, 1.812], [0.981, 1.101, 1.602], [0.911, 0.999, 1.201]],
    ),
    LINEAR_SPEEDS,
    "angular speed (rad/s)",
    "linear speed (m/s)",
    (ANGULAR_NOTE,),
)
TABLE_5 = PaperTable(
    5,
    "Single robot average start/stop response time with Web interface autonomous",
    "s",
    SPEED_COLUMNS,
    _grid(
        [[1.011, 1.001, 0.981], [1.001, 0.987, 0.956], [0.987, 0.872, 0.789], [0.861, 0.761, 0.712]],
        [[1.345, 1.765, 2.552], [1.241, 1.451, 2.222], [1.109, 1.431, 1.988], [1.011, 1.344, 1.765]],
    ),
    LINEAR_SPEEDS,
    "angular speed (rad/s)",
    "linear speed (m/s)",
    (ANGULAR_NOTE,),
)
TABLE_6 = PaperTable(
    6,
    "Multiple robots average start/stop response time with Web interface autonomous",
    "s",
    SPEED_COLUMNS,
    (
        Section(
            "StartResponse (s)",
            _robots([[1.011, 1.001, 0.981], [1.129, 1.078, 1.016], [1.456, 1.241, 1.112]]),
        ),
        Section(
            "StopResponse (s)", _robots([[1.345, 1.765, 2.552], [1.674, 1.987, 2.987], [1.987, 2.134, 2.456]])
        ),
    ),
    LINEAR_SPEEDS,
    "robots",
    "linear speed (m/s)",
    ("angular speed kept constant (the paper's Figure 21 text)",),
)
TABLE_7 = PaperTable(
    7,
    "Average moving time for multiple robots with single instruction",
    "s",
    (
        "Move to (x_0, y_0)",
        "Move to (x_0, y_0) and (x_1, y_1)",
        "Move to (x_0, y_0), (x_1, y_1), and (x_2, y_2)",
    ),
    (
        Section(
            "Average move time (s)", _robots([[2.01, 2.22, 3.01], [2.24, 3.01, 3.34], [3.05, 3.21, 4.01]])
        ),
    ),
    (1, 2, 3),
    "robots",
    "target locations",
    ("titled 'single instruction' while its columns name one, two and three targets, as printed",),
)
TABLE_8 = PaperTable(
    8,
    "Average completion time for multiple robots with multiple instructions",
    "s",
    ("Single instruction", "Two instructions", "Three instructions"),
    (
        Section(
            "Average competition time (s)",
            _robots([[2.32, 2.98, 3.56], [2.59, 3.24, 3.98], [3.23, 3.57, 4.62]]),
        ),
    ),
    (1, 2, 3),
    "robots",
    "sequential instructions",
    ("'competition' is the paper's spelling of completion",),
)
SLOTS = ("08.00-10.00", "10.00-12.00", "12.00-02.00", "02.00-04.00")
SLOT_COLUMNS = tuple(f"Goal 0{i} success rate {slot}" for i, slot in enumerate(SLOTS, start=1))
ROBOTS_7 = ("Turtlebot", "Husky", "TiaGo")


def _rates(name: str, values: list[list[float]]) -> tuple[Section, ...]:
    return (Section(name, tuple(Row(r, tuple(v), r) for r, v in zip(ROBOTS_7, values, strict=True))),)


TABLE_13 = PaperTable(
    13,
    "Experiment results for goal without navigation",
    "fraction of 20 trials",
    SLOT_COLUMNS,
    _rates(
        "Goal without navigation",
        [[0.65, 0.85, 0.90, 0.95], [0.50, 0.65, 0.70, 0.80], [0.45, 0.55, 0.65, 0.85]],
    ),
    SLOTS,
    "robot",
    "goal / time slot",
    ("20 type IV instructions per robot per slot",),
)
TABLE_14 = PaperTable(
    14,
    "Experiment results for goal with navigation",
    "fraction of 20 trials",
    SLOT_COLUMNS,
    _rates(
        "Goal with navigation", [[0.40, 0.55, 0.75, 0.80], [0.35, 0.40, 0.55, 0.70], [0.30, 0.45, 0.60, 0.75]]
    ),
    SLOTS,
    "robot",
    "goal / time slot",
    (
        "slot ends lost in the extraction; same slots as Table 13",
        "20 type IV instructions per robot per slot",
    ),
)

TABLES: dict[int, PaperTable] = {
    t.number: t for t in (TABLE_3, TABLE_4, TABLE_5, TABLE_6, TABLE_7, TABLE_8, TABLE_13, TABLE_14)
}

# Table 12: the goals and tasks per robot per slot that Tables 13 and 14 ran (None = FreeTime).
SCHEDULE_12: dict[str, tuple[tuple[str, float, float, str] | None, ...]] = {
    "Turtlebot": (("A", 2, 2, "rotate(5)"), None, ("B", -2, 2, "rotate(5)"), ("C", 2, -2, "rotate(5)")),
    "Husky": (("D", 5, 5, "rotate(10)"), ("E", 5, -5, "rotate(10)"), None, ("F", 0, 5, "rotate(10)")),
    "TiaGo": (None, ("G", 1, -1, "rotate(15)"), ("H", 0, 1, "rotate(15)"), ("I", -1, 1, "rotate(15)")),
}

# Table 9: the five instruction types, with the paper's examples.
INSTRUCTION_TYPES = {
    "I": "Move to A and clean",
    "II": "Shift to B and clean",
    "III": "Move to roof and clean",
    "IV": "Shift to sky and clean",
    "V": "Proceed to sea and clean",
}
