"""A bound on the frames one endpoint's link takes in: a rate (a token bucket holding one second's worth), beyond
which frames are dropped unread and counted. The rate is the setting's allowance (limits.frames_per_s, shared by
what the link asked for at no fixed rate: service answers, unthrottled topics) plus twice what its throttled
subscriptions ask for (expect()): one endpoint may serve a whole simulator shard of 500 robots, whose odometry at
10 Hz is 5,000 frames a second that the link itself asked for, and that is no flood. The queue ahead of it is
websockets' own (client.MAX_QUEUE frames, then TCP backpressure on the sender), so a flooding endpoint costs its
link's reader a bounded share of the loop and every other link, stop and live pose on that loop goes on as
without it.

A link that starts dropping tells the process's flood listeners (robots.flooding flags the robots of the endpoint
and raises an alert), and again every REPORT_S while it goes on.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable

log = logging.getLogger("robots.rosbridge")

QUIET_S = 5.0  # a link that dropped nothing for this long is no longer flooding
HEADROOM = 2.0  # times what the throttled subscriptions ask for (a throttle's interval is not a metronome)
REPORT_S = 10.0  # while it floods, the listeners hear its count again this often
LISTENERS: list[Callable[[str, int, bool], None]] = []  # (url, frames dropped so far, flooding now)


class Inflow:
    """The token bucket of one link: admit() for each frame; a False is a frame to drop (counted)."""

    def __init__(self, url: str, rate: int, clock: Callable[[], float] = time.monotonic) -> None:
        self.url, self.base, self.clock = url, float(rate), clock
        self.expected = 0.0  # frames a second the link's throttled subscriptions ask for
        self.rate = self.base
        self.tokens, self.at = self.rate, clock()
        self.dropped = self.taken = 0
        self.last_drop = self.reported = float("-inf")
        self.said_flooding = False

    def expect(self, hz: float) -> None:
        """A subscription asks for hz frames a second (negative: one that asked ended): the rate follows."""
        self.expected = max(0.0, self.expected + hz)
        self.rate = self.base + HEADROOM * self.expected

    @property
    def flooding(self) -> bool:
        return self.clock() - self.last_drop < QUIET_S

    def admit(self) -> bool:
        now = self.clock()
        self.tokens = min(self.rate, self.tokens + (now - self.at) * self.rate)
        self.at = now
        if self.tokens >= 1.0:
            self.tokens -= 1.0
            self.taken += 1
            if self.said_flooding and now - self.last_drop >= QUIET_S:
                self._report(False)  # the flood is over
            return True
        self.dropped += 1
        self.last_drop = now
        if not self.said_flooding or now - self.reported >= REPORT_S:
            self._report(True)
        return False

    def _report(self, flooding: bool) -> None:
        self.reported, self.said_flooding = self.clock(), flooding
        if flooding:
            log.warning("%s: more than %g frames/s; %d dropped so far", self.url, self.rate, self.dropped)
        for listener in list(LISTENERS):
            try:
                listener(self.url, self.dropped, flooding)
            except Exception:
                log.exception("%s: flood listener failed", self.url)
