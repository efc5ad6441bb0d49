"""The service harness, shared with tests/service: some cell modules are checked in a running
service too (a worker killed mid-calibration, a failed save)."""

from tests.service.conftest import make_service, service

__all__ = ["make_service", "service"]
