"""Screenshots of a results folder's ``winner.html`` for the docs, taken as the page test takes
them (headless Chromium from a ``file://`` URL), with the page's size and load time::

    python docs/screenshots.py results/paper-5kg      # after `make run`
    python docs/screenshots.py results/improv improv-winner   # docs/improv-winner-t0.png, -tf.png
"""

from __future__ import annotations

import shutil
import sys
import time
from pathlib import Path

from playwright.sync_api import sync_playwright

from modular_robots.viewer import HEADLESS_CHROMIUM

DOCS = Path(__file__).resolve().parent


def main(folder: Path, name: str = "winner") -> None:
    page_path = folder / "winner.html"
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=shutil.which("chromium"), args=list(HEADLESS_CHROMIUM))
        page = browser.new_page(viewport={"width": 1280, "height": 760})
        start = time.perf_counter()
        page.goto(page_path.resolve().as_uri())
        page.wait_for_function("window.viewer && window.viewer.ready")
        loaded = time.perf_counter() - start
        for label, t in (("t0", "0"), ("tf", "viewer.tf")):
            page.evaluate(f"viewer.setTime({t})")
            page.screenshot(path=str(DOCS / f"{name}-{label}.png"))
        browser.close()
    print(f"{page_path}: {page_path.stat().st_size / 1e6:.2f} MB, ready {loaded:.2f} s after opening")


if __name__ == "__main__":
    main(Path(sys.argv[1] if len(sys.argv) > 1 else "results/paper-5kg"), *sys.argv[2:3])
