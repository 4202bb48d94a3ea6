"""A results folder's ``winner.html`` in headless Chromium from a ``file://`` URL, as a user opens
it offline: what the console said, what the page asked the network for, the canvas at t = 0 and
at tf (RGB arrays) and the clock's text at tf."""

from __future__ import annotations

import io
import shutil
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from modular_robots.viewer import HEADLESS_CHROMIUM, VIEWER

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")


@dataclass
class Visit:
    errors: list[str]
    requests: list[str]
    start: np.ndarray
    end: np.ndarray
    clock: str


def visit(folder: Path, shots: Path) -> Visit:
    """Open ``folder``'s page, screenshot its canvas at t = 0 and tf into ``shots``."""
    from PIL import Image
    from playwright.sync_api import sync_playwright

    errors: list[str] = []
    requests: list[str] = []
    images = []
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, args=list(HEADLESS_CHROMIUM))
        try:
            page = browser.new_page(viewport={"width": 1200, "height": 760})
            page.on("console", lambda m: errors.append(m.text) if m.type == "error" else None)
            page.on("pageerror", lambda e: errors.append(str(e)))
            page.on("request", lambda r: requests.append(r.url))
            page.goto((folder / VIEWER).as_uri())
            page.wait_for_function("window.viewer && window.viewer.ready", timeout=20_000)
            for t in ("0", "viewer.tf"):
                page.evaluate(f"viewer.setTime({t})")
                images.append(page.locator("#view canvas").screenshot(path=str(shots / f"t{len(images)}.png")))
            clock = page.inner_text("#clock")
        finally:
            browser.close()
    start, end = (np.asarray(Image.open(io.BytesIO(s)).convert("RGB"), dtype=int) for s in images)
    return Visit(errors, requests, start, end, clock)
