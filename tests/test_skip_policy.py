"""The skip policy (tests/skip_policy.py) fails a run on an undocumented skip and lets documented ones pass."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from tests.skip_policy import SHARED_MISSING, is_allowed

pytest_plugins = ["pytester"]

REPO = Path(__file__).resolve().parents[1]

CONFTEST = "from tests.skip_policy import pytest_configure  # noqa: F401\n"

TESTS = """
import pytest

from tests.skip_policy import skip_shared_missing


def test_runs() -> None:
    assert True


def test_allowed() -> None:
    skip_shared_missing("some/sequence")


def test_unexpected() -> None:
    {unexpected}
"""


def _write(pytester: pytest.Pytester, unexpected: str) -> None:
    pytester.makeconftest(CONFTEST)
    pytester.makepyfile(test_policy=TESTS.format(unexpected=unexpected))


def test_reason_patterns() -> None:
    assert is_allowed(f"{SHARED_MISSING}/x/shared/data/kitti00_0000-0199")
    assert not is_allowed(SHARED_MISSING)  # a reason must say what is missing
    assert not is_allowed("could not import 'amrvio.sim.render': No module named 'amrvio.sim.render'")
    assert not is_allowed(f"real data absent; {SHARED_MISSING}x")  # the prefix must start the reason


def test_allowed_skip_passes(pytester: pytest.Pytester) -> None:
    _write(pytester, "pass")
    result = pytester.runpytest("-p", "no:xdist", "-p", "no:cacheprovider", "-rs")
    result.assert_outcomes(passed=2, skipped=1)
    assert result.ret == pytest.ExitCode.OK
    result.stdout.no_fnmatch_line("*UNEXPECTED SKIP*")


def test_unexpected_skip_fails_the_run(pytester: pytest.Pytester) -> None:
    _write(pytester, 'pytest.skip("flaky, look later")')
    result = pytester.runpytest("-p", "no:xdist", "-p", "no:cacheprovider", "-rs")
    result.assert_outcomes(passed=1, skipped=2)
    assert result.ret == pytest.ExitCode.TESTS_FAILED
    result.stdout.fnmatch_lines(["*UNEXPECTED SKIP test_policy.py::test_unexpected: flaky, look later"])
    result.stdout.no_fnmatch_line("*UNEXPECTED SKIP*test_allowed*")


def test_importorskip_of_a_missing_module_fails_the_run(pytester: pytest.Pytester) -> None:
    pytester.makeconftest(CONFTEST)
    pytester.makepyfile(test_fine="def test_fine() -> None:\n    assert True\n",
                        test_gone="import pytest\nmod = pytest.importorskip('amrvio.no_such_module')\n\n"
                                  "def test_x() -> None:\n    assert mod\n")
    result = pytester.runpytest("-p", "no:xdist", "-p", "no:cacheprovider", "-rs")
    result.assert_outcomes(passed=1, skipped=1)
    assert result.ret == pytest.ExitCode.TESTS_FAILED
    result.stdout.fnmatch_lines(["*UNEXPECTED SKIP test_gone.py:*amrvio.no_such_module*"])


def test_failure_keeps_its_exit_status(pytester: pytest.Pytester) -> None:
    _write(pytester, "pytest.fail('boom')")
    result = pytester.runpytest("-p", "no:xdist", "-p", "no:cacheprovider")
    assert result.ret == pytest.ExitCode.TESTS_FAILED
    result.assert_outcomes(passed=1, skipped=1, failed=1)


def test_under_xdist_an_unexpected_skip_fails_and_an_allowed_one_passes(
        pytester: pytest.Pytester, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join([str(REPO), os.environ.get("PYTHONPATH", "")]))
    pytester.makeconftest(CONFTEST)
    pytester.makepyfile(test_ok=TESTS.format(unexpected="pass"))
    ok = pytester.runpytest_subprocess("-n", "2", "-p", "no:cacheprovider", "-rs")
    assert ok.ret == pytest.ExitCode.OK, ok.stdout.str()
    ok.stdout.fnmatch_lines([f"SKIPPED*{SHARED_MISSING}some/sequence"])

    pytester.makepyfile(test_bad=TESTS.format(unexpected='pytest.skip("not today")'))
    bad = pytester.runpytest_subprocess("-n", "2", "-p", "no:cacheprovider", "-rs")
    assert bad.ret == pytest.ExitCode.TESTS_FAILED, bad.stdout.str()
    bad.stdout.fnmatch_lines(["*UNEXPECTED SKIP test_bad.py::test_unexpected: not today"])
    bad.stdout.no_fnmatch_line("*UNEXPECTED SKIP test_ok.py*")
