"""bound_heap: with glibc's thresholds fixed, freed large arrays leave the resident set; with
glibc's default, once a large block has been freed, they stay (the growth bench_speed saw)."""

from __future__ import annotations

import json
import platform
import subprocess
import sys

_SCRIPT = """
import json, sys
import numpy as np
from amrvio.pipeline.heap import bound_heap
def rss_mib():
    with open("/proc/self/statm") as fh:
        return int(fh.read().split()[1]) * 4096 / 2**20
ok = bound_heap() if sys.argv[1] == "bound" else None
big = np.ones(4 * 2**20 // 8)  # 4 MiB: freed, it raises glibc's default mmap threshold to 4 MiB
del big
before = rss_mib()
arrays = [np.ones(256 * 1024 // 8) for _ in range(60)]  # 15 MiB of 256 KiB arrays, touched
keep = arrays[-1]
del arrays  # all but the newest freed
print(json.dumps({"set": ok, "kept_mib": rss_mib() - before}))
"""


def _run(mode: str) -> dict[str, float | bool | None]:
    res = subprocess.run([sys.executable, "-c", _SCRIPT, mode], capture_output=True, text=True, check=True)
    out: dict[str, float | bool | None] = json.loads(res.stdout.strip().splitlines()[-1])
    return out


def test_fixed_thresholds_give_freed_large_arrays_back() -> None:
    bound = _run("bound")
    if not bound["set"]:  # not glibc: nothing is changed, and nothing to measure
        assert platform.libc_ver()[0] != "glibc"
        return
    default = _run("default")
    kept_bound, kept_default = float(bound["kept_mib"] or 0.0), float(default["kept_mib"] or 0.0)
    assert kept_bound < 2.0  # the newest array, 0.25 MiB, and noise
    assert kept_default > 10.0  # the freed 14.75 MiB stayed below the newest array
