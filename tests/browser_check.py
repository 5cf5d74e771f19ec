"""Open a report.html in a real headless browser (Chromium) and report what it rendered.

A copy of the page gets a script that, once the page has loaded, counts the images the browser
decoded (``complete`` with a non-zero natural size) and writes the count and the names of the
plots into the document title; ``chromium --dump-dom`` prints the resulting DOM. A screenshot of
the whole page can be written too.

    python -m tests.browser_check demo_out/run/report.html [--screenshot page.png]

Used by tests/test_app_run.py when a Chromium is installed (Debian: ``apt-get install chromium``).
"""

from __future__ import annotations

import argparse
import re
import shutil
import subprocess
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path

BROWSERS = ("chromium", "chromium-browser", "google-chrome")

_PROBE = """<script>
window.addEventListener("load", function () {
  var imgs = Array.from(document.images);
  var ok = imgs.filter(function (i) { return i.complete && i.naturalWidth > 0 && i.naturalHeight > 0; });
  document.title = "RENDERED " + ok.length + "/" + imgs.length + " " +
    ok.map(function (i) { return i.dataset.plot + ":" + i.naturalWidth + "x" + i.naturalHeight; }).join(",");
});
</script>"""


@dataclass(frozen=True, slots=True)
class Rendered:
    """What the browser made of the page: images decoded out of all, and each decoded plot's
    name with its pixel size."""

    n_ok: int
    n_images: int
    plots: dict[str, tuple[int, int]]


def find_browser() -> str | None:
    for name in BROWSERS:
        path = shutil.which(name)
        if path is not None:
            return path
    return None


def _flags(browser: str) -> list[str]:
    return [browser, "--headless", "--no-sandbox", "--disable-gpu", "--hide-scrollbars",
            "--virtual-time-budget=10000"]


def render(report: Path, browser: str, screenshot: Path | None = None,
           width: int = 1200, height: int = 6000) -> Rendered:
    """Load ``report`` in ``browser``; optionally save a ``width`` x ``height`` screenshot."""
    with tempfile.TemporaryDirectory() as td:
        probe = Path(td) / "probe.html"
        probe.write_text(report.read_text(encoding="utf-8").replace("</body>", _PROBE + "</body>"),
                         encoding="utf-8")
        r = subprocess.run([*_flags(browser), "--dump-dom", probe.as_uri()], capture_output=True,
                           text=True, timeout=120, check=False)
    m = re.search(r"<title>RENDERED (\d+)/(\d+) ?([^<]*)</title>", r.stdout)
    if m is None:
        raise RuntimeError(f"{browser} did not run the probe (exit {r.returncode}): "
                           f"{r.stderr.strip()[-300:]}")
    plots: dict[str, tuple[int, int]] = {}
    for item in filter(None, m.group(3).split(",")):
        name, _, size = item.partition(":")
        w, _, h = size.partition("x")
        plots[name] = (int(w), int(h))
    if screenshot is not None:
        subprocess.run([*_flags(browser), f"--window-size={width},{height}",
                        f"--screenshot={screenshot}", report.resolve().as_uri()],
                       capture_output=True, timeout=120, check=True)
    return Rendered(int(m.group(1)), int(m.group(2)), plots)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else None)
    ap.add_argument("report", type=Path)
    ap.add_argument("--screenshot", type=Path, default=None)
    ap.add_argument("--height", type=int, default=6000)
    args = ap.parse_args(argv)
    browser = find_browser()
    if browser is None:
        print(f"no browser found (tried {', '.join(BROWSERS)})", file=sys.stderr)
        return 1
    res = render(args.report, browser, args.screenshot, height=args.height)
    print(f"{browser}: {res.n_ok} of {res.n_images} images rendered: "
          + ", ".join(f"{k} {w}x{h}" for k, (w, h) in res.plots.items()))
    return 0 if res.n_ok == res.n_images else 1


if __name__ == "__main__":
    sys.exit(main())
