"""bench.cluster's staleness told apart by what the bench was doing when each pose came."""

from bench import cluster
from bench.cluster import INSTRUCTIONS_PHASE, by_phase


def test_staleness_is_split_into_the_rounds_and_half_seconds_after_each_stop_all():
    stops_began, stops = 100.0, [101.0, 104.0]
    samples = [
        (99.0, 10.0), (99.9, 20.0),     # the rounds of commands
        (100.5, 30.0),                  # the first trial's presses, before its stop-all
        (101.0, 300.0), (101.49, 200.0), (104.2, 400.0),  # within half a second of a stop-all
        (101.6, 40.0), (104.9, 50.0),   # half a second to a second after one
        (103.9, 60.0),                  # three seconds after the first
        (106.0, 900.0), (107.0, 800.0), # the instructions, after the trials
    ]  # fmt: skip
    phases = by_phase(samples, stops_began, stops, stops_ended=105.5)
    assert list(phases) == [
        "rounds", "stop trials, before the first stop-all", "0.0-0.5 s after a stop-all",
        "0.5-1.0 s after a stop-all", "2.5-3.0 s after a stop-all", INSTRUCTIONS_PHASE,
    ]  # fmt: skip
    assert phases[INSTRUCTIONS_PHASE]["n"] == 2 and phases[INSTRUCTIONS_PHASE]["min"] == 800.0
    assert phases["rounds"]["n"] == 2 and phases["rounds"]["max"] == 20.0
    assert (
        phases["0.0-0.5 s after a stop-all"]["n"] == 3
        and phases["0.0-0.5 s after a stop-all"]["min"] == 200.0
    )
    assert (
        phases["0.5-1.0 s after a stop-all"]["n"] == 2 and phases["0.5-1.0 s after a stop-all"]["max"] == 50.0
    )


def test_no_sample_gives_no_phase_not_an_error():
    assert by_phase([], 0.0, [], 0.0) == {}


def test_the_angle_an_outcome_says_is_read_for_succeeded_and_failed_turns():
    """bench.cluster judges each robot's words against its odometry: a failed turn says how far it went too."""
    outcome = (
        "robot1: succeeded (turned 90° left); "
        "robot2: succeeded (turned 104° left (90° left asked)); "
        "robot3: failed (robot3: did not finish within 12 s: turned 60° left (90° left asked)); "
        "robot4: failed (robot4: stuck turning 90° left (no progress for 3 s near (1.0, -4.1)): turned 12° right "
        "(90° left asked)); "
        "robot5: failed (executor lost: the process running it stopped renewing its lock; the robot was stopped)"
    )
    assert cluster.said_in(outcome) == {"robot1": 90.0, "robot2": 104.0, "robot3": 60.0, "robot4": -12.0}
