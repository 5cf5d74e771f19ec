"""Skip policy: a skip the project did not document fails the run.

A skipped test did not run, so an unexpected skip (an `importorskip` of a broken module, a fixture
that gives up) hides a failure. The only skips allowed are those whose reason matches a pattern in
ALLOWED_SKIP_REASONS, kept here and nowhere else:

- the real-data tests when ../shared/data, or the part of it a test reads, is absent. They skip
  through `skip_shared_missing`, whose reason starts with SHARED_MISSING.

tests/conftest.py re-exports `pytest_configure` so that pytest loads the policy. The run lists every
skip with its reason (`-rs`, see the Makefile), and ends with exit status 1 when one of them is not
allowed (a run that already failed keeps its own status). It works under pytest-xdist: the controller
sees every worker's reports, and the policy runs on the controller only.
"""

from __future__ import annotations

import re
from typing import NoReturn

import pytest

SHARED_MISSING = "../shared/data missing: "

ALLOWED_SKIP_REASONS: tuple[re.Pattern[str], ...] = (
    re.compile(r"^\.\./shared/data missing: \S"),  # SHARED_MISSING, then what is missing
)

PLUGIN_NAME = "amrvio-skip-policy"


def skip_shared_missing(what: object) -> NoReturn:
    """Skip the calling test because `what` (a path, or a description) under ../shared/data is absent."""
    pytest.skip(f"{SHARED_MISSING}{what}")


def skip_reason(report: pytest.TestReport | pytest.CollectReport) -> str:
    """The reason a skipped report gives, without pytest's "Skipped: " prefix."""
    longrepr = report.longrepr
    if isinstance(longrepr, tuple | list) and len(longrepr) == 3:
        message = str(longrepr[2])
    else:
        message = str(longrepr)
    return message.removeprefix("Skipped: ")


def is_allowed(reason: str) -> bool:
    return any(p.search(reason) for p in ALLOWED_SKIP_REASONS)


class SkipPolicy:
    """Collects the skips whose reason is not allowed; fails the session when there are any."""

    def __init__(self) -> None:
        self.unexpected: list[tuple[str, str]] = []  # (node id, reason)

    def _record(self, report: pytest.TestReport | pytest.CollectReport) -> None:
        if not report.skipped or hasattr(report, "wasxfail"):  # an xfail is not a skip
            return
        reason = skip_reason(report)
        if not is_allowed(reason):
            self.unexpected.append((report.nodeid, reason))

    def pytest_runtest_logreport(self, report: pytest.TestReport) -> None:
        self._record(report)

    def pytest_collectreport(self, report: pytest.CollectReport) -> None:
        self._record(report)

    @pytest.hookimpl(tryfirst=True)
    def pytest_sessionfinish(self, session: pytest.Session) -> None:
        if self.unexpected and session.exitstatus == pytest.ExitCode.OK:
            session.exitstatus = pytest.ExitCode.TESTS_FAILED

    def pytest_terminal_summary(self, terminalreporter: pytest.TerminalReporter) -> None:
        if not self.unexpected:
            return
        terminalreporter.section("unexpected skips (tests/skip_policy.py)", sep="=", red=True, bold=True)
        for nodeid, reason in self.unexpected:
            terminalreporter.line(f"UNEXPECTED SKIP {nodeid}: {reason}")
        allowed = ", ".join(repr(p.pattern) for p in ALLOWED_SKIP_REASONS)
        terminalreporter.line(f"{len(self.unexpected)} skip(s) match none of the allowed reasons ({allowed}): "
                              "the run fails. Make the test run, or document the skip in tests/skip_policy.py.")


def pytest_configure(config: pytest.Config) -> None:
    if hasattr(config, "workerinput"):  # an xdist worker: its reports reach the controller
        return
    config.pluginmanager.register(SkipPolicy(), PLUGIN_NAME)
