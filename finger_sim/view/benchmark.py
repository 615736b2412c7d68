"""How long a viewer page takes to open in Chromium, against the same page with plotly's full bundle.

    python -m finger_sim.view.benchmark PAGE.html [--repeats 7]

Opens PAGE and a copy whose inline plotly.js is the plotly package's full bundle, alternately,
each in a fresh page of one headless Chromium (network blocked), and reports the median time
from navigation start to the viewer's ready mark (the first frame drawn and the plots made),
measured by the page's own clock, and the CPU time the page's renderer process spent. Needs Debian's Chromium and Playwright (the test extra).
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
from importlib import resources
from pathlib import Path

from finger_sim.view.page import PLOTLY_BUNDLE

CHROMIUM = "/usr/bin/chromium"
CHROMIUM_ARGS = ["--no-sandbox", "--disable-gpu", "--disable-background-networking", "--disable-component-update",
                 "--no-first-run", "--disable-sync"]
READY_TIMEOUT_MS = 60_000


def open_times(pages: dict[str, Path], repeats: int) -> dict[str, list[tuple[float, float]]]:
    """Per page label: (time to ready by the page's clock, CPU time of the page's renderer process
    by Chrome's ProcessTime metric), s, of `repeats` opens, the pages taking turns. On a busy machine
    the first grows with the load; the second is what the page costs."""
    from playwright.sync_api import sync_playwright

    times: dict[str, list[tuple[float, float]]] = {label: [] for label in pages}
    with sync_playwright() as playwright:
        browser = playwright.chromium.launch(executable_path=CHROMIUM, headless=True, args=CHROMIUM_ARGS)
        try:
            for _ in range(repeats):
                for label, path in pages.items():
                    uri = path.resolve().as_uri()
                    page = browser.new_page()
                    cdp = page.context.new_cdp_session(page)
                    cdp.send("Performance.enable")
                    page.route("**/*", _only(uri))
                    page.goto(uri)
                    page.wait_for_selector("body[data-ready=true]", state="attached", timeout=READY_TIMEOUT_MS)
                    ready = page.evaluate("performance.now()") / 1000.0
                    metrics = {m["name"]: m["value"] for m in cdp.send("Performance.getMetrics")["metrics"]}
                    times[label].append((ready, metrics["ProcessTime"]))
                    page.close()
        finally:
            browser.close()
    return times


def _only(uri: str):  # type: ignore[no-untyped-def]
    """A route handler that lets the page load itself and aborts every other request."""
    return lambda route: route.continue_() if route.request.url == uri else route.abort()


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("page", type=Path)
    parser.add_argument("--repeats", type=int, default=7)
    args = parser.parse_args(argv)
    from plotly.offline import get_plotlyjs

    text = args.page.read_text(encoding="utf-8")
    basic = (resources.files("finger_sim.view") / "vendor" / PLOTLY_BUNDLE).read_text(encoding="utf-8")
    if basic not in text:
        print(f"{args.page}: not a viewer page with the vendored {PLOTLY_BUNDLE}", file=sys.stderr)
        return 2
    with tempfile.TemporaryDirectory() as tmp:
        full = Path(tmp) / "full_bundle.html"
        full.write_text(text.replace(basic, get_plotlyjs()), encoding="utf-8")
        pages = {"viewer (plotly.js basic bundle)": args.page, "same page, plotly.js full bundle": full}
        times = open_times(pages, args.repeats)
        print("| page | size (MB) | open, median (min-max), s | renderer CPU, median (min-max), s |")
        print("|---|---|---|---|")
        for label, path in pages.items():
            ready, cpu = zip(*times[label])
            print(f"| {label} | {path.stat().st_size / 1e6:.2f} | {statistics.median(ready):.2f} ({min(ready):.2f}-{max(ready):.2f}) "
                  f"| {statistics.median(cpu):.2f} ({min(cpu):.2f}-{max(cpu):.2f}) |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
