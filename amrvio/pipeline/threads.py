"""Thread settings of the native libraries the VO leans on, set explicitly by the caller.

The VO does many small dense solves (local BA, PnP, triangulation); with OpenBLAS threads on
a shared 2-core machine they ran several times slower than with one thread (bench_vo). The CLI
and the benchmark call :func:`run_settings` (these threads and glibc's heap thresholds); the
library itself never does.
"""

from __future__ import annotations


def limit_native_threads(n: int = 1) -> int:
    """Set OpenCV and the BLAS libraries loaded by NumPy/SciPy (via threadpoolctl) to ``n`` threads.

    Returns how many BLAS libraries were limited (0 when none was found: nothing changes).
    The limit holds for the rest of the process.
    """
    import cv2
    import numpy  # noqa: F401  (loads its BLAS so that threadpoolctl can see it)
    import scipy.linalg  # noqa: F401
    from threadpoolctl import threadpool_info, threadpool_limits

    cv2.setNumThreads(n)
    threadpool_limits(limits=n, user_api="blas")
    return sum(1 for info in threadpool_info() if info.get("user_api") == "blas")


def run_settings() -> None:
    """The process settings of ``amrvio run`` and ``amrvio batch``: OpenCV and the BLAS on one
    thread (:func:`limit_native_threads`) and glibc's heap thresholds fixed
    (:func:`amrvio.pipeline.heap.bound_heap`). The benchmarks call it to measure what the CLI runs."""
    from amrvio.pipeline.heap import bound_heap

    limit_native_threads(1)
    bound_heap()


__all__ = ["limit_native_threads", "run_settings"]
