"""Debian's chromium, headless, driven by Playwright: the dashboards' page as users see it.

Skips the calling test where chromium is not installed (``apt-get install chromium``; CI
installs it). The flags keep chromium itself off the network (no background requests,
component updates or sync).
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import pytest

CHROMIUM = Path("/usr/bin/chromium")


@contextmanager
def chromium() -> Iterator[Any]:
    """A launched headless browser (Playwright's ``Browser``), closed on exit."""
    if not CHROMIUM.exists():
        pytest.skip("Debian's chromium is not installed (apt-get install chromium)")
    from playwright.sync_api import sync_playwright

    with sync_playwright() as playwright:
        launched = playwright.chromium.launch(
            executable_path=str(CHROMIUM),
            headless=True,
            args=[
                "--no-sandbox",
                "--disable-gpu",
                "--disable-quic",
                "--no-first-run",
                "--disable-background-networking",
                "--disable-component-update",
                "--disable-sync",
            ],
        )
        try:
            yield launched
        finally:
            launched.close()


def wait_for_connection(page: Any, text: str, timeout: float = 30_000, context: str = "") -> None:
    """Wait until the dashboard page's connection line reads ``text``. The link's state is
    set on the links' thread and results are drawn from the samples' path, so the line may
    follow a result by a moment; if it never comes, fail with each link's state and error
    as the page shows them, and ``context`` (say, the dashboard's output)."""
    from playwright.sync_api import TimeoutError as PlaywrightTimeout

    try:
        page.wait_for_function(
            f"() => document.getElementById('connection').textContent === {json.dumps(text)}",
            timeout=timeout,
        )
    except PlaywrightTimeout:
        shown = page.text_content("#connection")
        links = page.text_content("#zenoh")
        raise AssertionError(
            f"connection {shown!r}, not {text!r}; links {links!r}; {context}"
        ) from None
