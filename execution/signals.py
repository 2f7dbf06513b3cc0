"""The execution room's signals: how a lower module asks for what a higher one does, without importing it."""

from django.dispatch import Signal

# Traffic asks a robot parked in the way to make way (execution.traffic.ask_to_make_way), sent with `robot` (the
# robot that asks), `asked` (the name of the robot asked) and `cause` (the words of why). The receiver,
# execution.instructions.on_make_way_asked (connected in ExecutionConfig.ready), submits the make_way
# instruction through the same command surface a person's goes through, and returns the words of its refusal,
# or None when it was taken.
make_way_asked = Signal()
