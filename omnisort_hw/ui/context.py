"""What every page of one interface process shares: its settings, the link to the service,
the operators signed in and the job it started."""

from __future__ import annotations

from dataclasses import dataclass

from omnisort_hw.config.ui import UiConfig
from omnisort_hw.sim_link import SimLink
from omnisort_hw.ui.job_runner import JobRunner
from omnisort_hw.ui.link import ServiceLink
from omnisort_hw.ui.live_feed import LiveFeed
from omnisort_hw.ui.operators import Operators


@dataclass
class UiContext:
    config: UiConfig
    link: ServiceLink
    operators: Operators
    jobs: JobRunner
    feed: LiveFeed
    sim: SimLink | None = None  # the virtual cell's control channel, `[ui] sim_control`

    @classmethod
    def for_service(cls, config: UiConfig, host: str, port: int) -> UiContext:
        """The context of an interface for the service at host:port (its status read at once)."""
        link = ServiceLink(host, port, config.status_period_s)
        link.start()
        return cls(
            config,
            link,
            Operators(link, config.allow_operator),
            JobRunner(link),
            LiveFeed(link, config.view_period_s, config.view_width_px),
            SimLink(*config.sim_control) if config.sim_control else None,
        )

    def close(self) -> None:
        if self.sim is not None:
            self.sim.close()
        self.feed.close()
        self.link.close()
