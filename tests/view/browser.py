"""Headless Chromium with WebGL2 (SwiftShader) for the tests of ``gonio view``'s page.

Debian's ``chromium`` and ``chromium-driver`` (``/usr/bin/chromium``, ``/usr/bin/chromedriver``)
and ``selenium``; without them the tests skip, except under ``CI=true``, where they fail.
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest

CHROMIUM = Path("/usr/bin/chromium")
CHROMEDRIVER = Path("/usr/bin/chromedriver")


def missing(reason: str) -> None:
    """Skip, or fail under CI (a CI machine must run the browser tests)."""
    if os.environ.get("CI", "").strip().lower() == "true":
        pytest.fail(f"CI=true and {reason}")
    pytest.skip(reason)


def start(profile: Path, window: tuple[int, int] = (1400, 1000)):
    """A headless Chromium driver rendering WebGL2 through SwiftShader (software), with its
    profile in ``profile`` and a ``window`` of (width, height) CSS pixels."""
    if not (CHROMIUM.exists() and CHROMEDRIVER.exists()):
        missing("Debian's chromium and chromium-driver are not installed")
    try:
        from selenium import webdriver
        from selenium.webdriver.chrome.service import Service
    except ImportError:
        missing("selenium is not installed")
    options = webdriver.ChromeOptions()
    options.binary_location = str(CHROMIUM)
    for flag in (
        "--headless=new",
        "--no-sandbox",
        "--use-angle=swiftshader",
        "--enable-unsafe-swiftshader",
        "--disable-quic",
        "--no-first-run",
        "--disable-background-networking",
        "--disable-component-update",
        "--disable-sync",
        f"--user-data-dir={profile}",
        f"--window-size={window[0]},{window[1]}",
    ):
        options.add_argument(flag)
    options.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    return webdriver.Chrome(service=Service(str(CHROMEDRIVER)), options=options)


def open_page(driver, path: Path, timeout: float = 60.0, mode: str = "point") -> list[dict]:
    """Open a page with its spheres in light ``mode`` (``point``, the default, leaves the
    environment's background refinement off), wait for its spheres and plots, return the
    console's errors since the last call."""
    from selenium.webdriver.support.ui import WebDriverWait

    driver.get(path.resolve().as_uri() + "#" + mode)
    WebDriverWait(driver, timeout).until(
        lambda d: d.execute_script("return !!(window.gonioView && window.gonioView.ready)")
    )
    return [e for e in driver.get_log("browser") if e["level"] in ("SEVERE", "ERROR")]
