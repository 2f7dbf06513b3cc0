"""What can go wrong talking to a rosbridge endpoint, each with a one-line message."""


class RosbridgeError(Exception):
    """Any failure of a rosbridge link; str() is one line naming the endpoint."""


class UnreachableError(RosbridgeError):
    """Nothing answers at the address (refused, no route, DNS)."""


class NotRosbridgeError(RosbridgeError):
    """Something answers, but not rosbridge (HTTP without WebSocket, garbage frames)."""


class RosbridgeTimeout(RosbridgeError, TimeoutError):
    """No answer in time; real rosbridge servers never reply to a bad request (protocol §7)."""


class LinkDown(RosbridgeError):
    """The connection closed while a request was waiting or before it was sent."""


class FrameTooLarge(LinkDown):
    """The server sent a frame (or fragmented message) above the frame limit; the link was closed."""


class BadFrame(RosbridgeError):
    """One frame with a field of the wrong type or size: dropped (logged), the link goes on."""


class ServiceError(RosbridgeError):
    """A service call (or action goal) the server answered with `result: false`; str() is its text."""
