"""Trajectory evaluation: association, alignment, ATE/RPE, scale error and scale drift."""

from amrvio.eval.associate import associate, match_stamps
from amrvio.eval.evaluate import EvalResult, EvaluationError, evaluate
from amrvio.eval.metrics import (
    AlignMethod,
    DeltaUnit,
    ErrorStats,
    RpeResult,
    ScaleWindow,
    WindowStatus,
    align_trajectory,
    ate,
    ate_errors_m,
    rpe,
    rpe_pairs,
    scale_windows,
)

__all__ = [
    "AlignMethod",
    "DeltaUnit",
    "ErrorStats",
    "EvalResult",
    "EvaluationError",
    "RpeResult",
    "ScaleWindow",
    "WindowStatus",
    "align_trajectory",
    "associate",
    "ate",
    "ate_errors_m",
    "evaluate",
    "match_stamps",
    "rpe",
    "rpe_pairs",
    "scale_windows",
]
