"""Execution: instructions become motion. Plain rules live in fleet.statemachine and fleet.motion.

- dispatch: from interpreted steps to per-robot executions (schedules, leases, formation, preemption)
- runner: drain each robot's queue under its Redis lock, in Celery workers (fleet.tasks)
- steps: one step through the robot's link (own controller or nav stack), with stop/preempt checks
- link: publish on the robot's bound topics in its message types; poses from odometry (+ amcl)
- coordination: Redis locks and flags; watchdog: executions whose worker died
- states: stored, live-pushed state transitions
"""
