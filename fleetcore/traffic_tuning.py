"""Every tuning constant of traffic, in one place (plain numbers, no Django): planning, claims, waits, driving a
route and making way (execution.traffic, traffic_state, traffic_fleet, driving, make_way) read them from here as
`tune.NAME`, so a test that sets one sets it for all of them.

Each says its unit and what it bounds, and where a run of the coordination bench set it, which run (the runs
and their journal: bench/results/runs/, docs/coordination.md). They were tuned together, over many
runs: change one only with the bench to show it (`python -m bench.coordination`).
"""

# Plans: space-time search against the others' reservations, in turn
HORIZON_S = 900.0  # s: plans heed the others' reservations all the way (no window)
SPACING_M = 0.1  # m more on each side in plans and reservations than claims ask (room to be off the line)
PAD_GROWTH = 0.02  # s of a reservation's slack per second ahead (pad)
PLANNED_SPEED = 0.8  # of the commanded speed: turns on the spot and ramps make robots slower than their top
SLOW_PLAN_MPS = 0.35  # m per s of wall time a fast robot is planned at when its own pace finds no plan
PLAN_MARGIN = 0.1  # m more again when planning round robots that stand (robots stop up to 0.2 m off a point)
END_M = 1.0  # m from its start and its goal a plan may pass where the robot has room to pass but not to turn
HOLD_S = 4.0  # s the cells another robot holds now are reserved for, in a newcomer's plan
PLAN_AGAIN_S = 2.0  # s a robot with no plan clear of the others stands before it plans again
MAX_REPLANS = 80  # plans of one trip: reroutes, and tries while no plan is clear of the others
SETTLE_M = 0.05  # m from its goal a robot stopped at a free spot next to it (a robot stood there)...
SETTLE_TRIES = 2  # ... plans again for the goal, this many times at most (the other may have left)
PASS_WAIT_S = 30.0  # s such a robot waits for the robots under way yet to pass near it before it plans again
TURN_WAIT_S = 30.0  # s a robot waits for its turn to plan (robots sent together are planned one by one)
TURN_TTL_MS = 10_000  # a turn its planner no longer holds (a dead worker) lapses after this
TURN_POLL_S = 0.05
TURN_WAITER_TTL_MS = 1_000  # a robot waiting for its turn that stopped asking (its executor died) is dropped
FIRST_IN_TURN_S = 1e9  # s: the trip time a robot making way queues for its turn with, ahead of any trip
PROGRESS_EVERY_S = 0.1  # s between a planning robot's checks of its stop flag (_now_and_then)
MAP_POINTS = 60  # points at most of a reserved route kept for the map (routes())

# Claims: the room a robot sweeps on a stretch, checked and written in one transaction
LEG_M = 1.2  # m: the longest stretch claimed at once
RESERVE_MARGIN = 0.05  # m added to a robot's reach radius in reservations and claims
CLAIM_MARGIN = 0.05  # m more kept between two robots' room when claiming (2 x 0.05 + 0.05 < spots' margin)
APPROACH_SLACK = 0.03  # m a robot already too close may come nearer (a route planned on cells wobbles)
ORDER_ZONE = 0.15  # m more than both reaches within which two plans' passages are ordered (< 2 x SPACING_M)
CLAIM_TTL_S = 30.0  # a claim its robot no longer renews (a dead worker) lapses after this
RENEW_BEFORE_S = 20.0  # a waiting robot renews its claim once less than this is left of it
CLAIM_LIMIT_S = 10.0  # s of claims lost to others' writes (WATCH) before a claim gives up

# Waits, reroutes and deadlocks
WAIT_LIMIT_S = 120.0  # s a robot waits for cells before its step fails
WAIT_POLL_S = 0.2  # s between a waiting robot's tries
NOTE_WAIT_S = 0.6  # s between a waiting robot's notes of whom it waits for (and its deadlock checks)
TELL_WAIT_S = 10.0  # s between a waiting robot's log lines (whom it waits for, and what that one does)
REROUTE_AFTER_S = 4.0  # s waiting for a robot that is not under way before going around it
BUSY_WAIT_S = 20.0  # s waiting for a robot busy with an instruction (it may set off) before going around it
MAX_REROUTES = 4  # robots standing gone round on one trip before it fails ("no way through")
# deadlocks one trip broke by giving way before it fails: counted apart, as the one to give way takes turns
# (traffic_state.break_deadlock), two robots bound for spots side by side each gave way 4 times and one failed
MAX_GIVE_WAYS = 8
BACK_OFF_M = 0.4  # m a robot breaking a deadlock drives away from the others first (_back_off)
REST_M = 0.002  # m between two odometry poses of a robot at rest
REST_RAD = 0.004  # rad between them: a robot turning on the spot is not at rest for standing where it was
REST_LIMIT_S = 2.0  # s a robot told to stop may take to come to rest

# Driving a route: corners, nav stacks and their pace
WAYPOINT_TOLERANCE = 0.2  # m: a corner of the route needs no precision, only the goal does...
CORNER_TOLERANCE = 0.05  # m: ... but a corner (a turn sharper than CORNER_TURN) does (_tolerance)
CORNER_TURN = 0.35  # rad: a turn of the route sharper than this is a corner
EARLY_S = 1.0  # s a robot may set off on a stretch before the time its plan gives
NAV_STALL_S = 15.0  # s a nav stack may spend on its own recoveries without progress (move_base's take ~10 s)
NAV_TOP_MPS = 0.22  # m/s a nav stack's planner is taken to drive at most (fleetcore.speed.Pace.stack_limits)
NAV_PACE_GUESS = 0.5  # of a nav stack's top speed (at most NAV_TOP_MPS): its stretches are given time at it
PACE_MIN_M = 0.3  # m: a nav stretch shorter than this says little of the stack's pace
PACE_WEIGHT = 0.5  # of a new measure of a nav stack's pace against what was known

# Making way: robots parked in the way asked to move aside
DETOUR_FACTOR = 1.5  # a way round robots parked in the way longer than this times the way through them...
DETOUR_M = 4.0  # ... plus this many metres (or none at all): the parked ones are asked to make way
MAKE_WAY_HOLD_S = 10.0  # s a robot asked to make way is taken to need to leave (claims hold it after)
MAKE_WAY_TTL_S = 240.0  # s a request to make way lasts (made way and back; refused: not asked again)
MAKE_WAY_WAIT_S = 120.0  # s a robot that made way waits for the other to pass before it goes back
MAKE_WAY_POLL_S = 0.5
ASIDE_STEP = 0.25  # m between the rings (and the points on them) searched for a spot off another's way
ASIDE_SEARCH_M = 6.0  # m from where it stands a robot making way looks for that spot
