"""rosbridge v2 client (asyncio, `websockets`) with roslibpy's wire format; no Django here."""

from robots.rosbridge.client import ActionGoal, RosbridgeClient, Subscription
from robots.rosbridge.errors import (
    BadFrame,
    FrameTooLarge,
    LinkDown,
    NotRosbridgeError,
    RosbridgeError,
    RosbridgeTimeout,
    ServiceError,
    UnreachableError,
)

__all__ = [
    "ActionGoal",
    "BadFrame",
    "FrameTooLarge",
    "LinkDown",
    "NotRosbridgeError",
    "RosbridgeClient",
    "RosbridgeError",
    "RosbridgeTimeout",
    "ServiceError",
    "Subscription",
    "UnreachableError",
]
