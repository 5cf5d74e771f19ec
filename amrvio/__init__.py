"""amrvio: robust monocular VO/VIO for mobile robots, with a per-frame health record.

``amrvio.run(dataset, config=None) -> RunResult`` runs the whole product on a recording (see
:func:`amrvio.app.run.run`); ``amrvio.pipeline.pipeline.Pipeline`` takes images frame by frame.
The names are imported on first use, so that ``import amrvio`` (and the CLI's start) stays light.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from amrvio.app.run import RunResult, run

__all__ = ["RunResult", "run"]


def __getattr__(name: str) -> Any:
    if name in ("run", "RunResult"):
        from amrvio.app import run as _run_module

        return getattr(_run_module, name)
    raise AttributeError(f"module 'amrvio' has no attribute {name!r}")
