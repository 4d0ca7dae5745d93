"""OUT/report.html in a real headless browser: Chromium and its driver from the system's
packages (.ci/run installs them), started by the test. The page loads with no console error,
shows every route of a small run, its filters work and its divergence clips play."""

from __future__ import annotations

import os
import shutil
import tempfile
import time
from pathlib import Path

import pytest

from icrsumo.app.cli.main import main

pytestmark = pytest.mark.sumo

ROUTES = ("tiny_003", "tiny_012")


def _browser():
    """A headless Chromium driven through chromedriver (a skip only outside CI: in CI the
    browser must be there). Its profile and scratch folders go into one short-named temporary
    folder (a Unix socket's path inside it must stay under 108 bytes) that ``quit()`` removes."""
    chromium = shutil.which("chromium") or shutil.which("chromium-browser")
    driver = shutil.which("chromedriver")
    try:
        from selenium import webdriver
        from selenium.webdriver.chrome.service import Service
    except ImportError:
        chromium = None
    if not (chromium and driver):
        if os.environ.get("CI"):
            pytest.fail("CI must have Chromium, chromedriver and selenium (.ci/run installs them)")
        pytest.skip("no Chromium/chromedriver here (apt-get install chromium chromium-driver)")
    opts = webdriver.ChromeOptions()
    opts.binary_location = chromium
    for arg in ("--headless=new", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage",
                "--window-size=1300,1800"):
        opts.add_argument(arg)
    opts.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    tmp = Path(tempfile.mkdtemp(prefix="icr-chrome-"))
    opts.add_argument(f"--user-data-dir={tmp / 'profile'}")
    env = {**os.environ, "TMPDIR": str(tmp)}  # Chromium's own scratch folders
    try:
        browser = webdriver.Chrome(service=Service(driver, env=env), options=opts)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    quit_browser = browser.quit

    def quit_and_clean() -> None:
        try:
            quit_browser()
        finally:
            shutil.rmtree(tmp, ignore_errors=True)

    browser.quit = quit_and_clean
    return browser


@pytest.fixture(scope="module")
def report(tmp_path_factory):
    out = tmp_path_factory.mktemp("html") / "out"
    assert main(["evaluate", "--suite", "tiny", "--routes", ",".join(ROUTES), "--agent", "route-oracle",
                 "--agent", "instruction-follower", "--family", "misleading", "--k", "2", "--workers", "2",
                 "--quiet", "--out", str(out)]) == 0
    return out / "report.html"


def test_the_page_is_self_contained(report):
    page = report.read_text(encoding="utf-8")
    assert "<script src" not in page and "<link" not in page and "http://" not in page.replace(
        'xmlns="http://www.w3.org/2000/svg"', "")
    for route in ROUTES:
        assert f'data-route="{route}"' in page


def test_it_loads_in_chromium_without_errors_and_its_filters_and_clips_work(report):
    driver = _browser()
    try:
        driver.get(report.as_uri())
        routes = driver.find_elements("css selector", "section.route")
        assert sorted(r.get_attribute("data-route") for r in routes) == list(ROUTES)
        assert all(r.is_displayed() for r in routes)
        assert driver.find_element("id", "shown").text == str(len(ROUTES))
        # the misleading variants flipped the instruction-follower: keep only flipped episodes
        driver.execute_script("var s=document.getElementById('f-outcome');s.value='flipped';"
                              "s.dispatchEvent(new Event('change'));")
        rows = [r for r in driver.find_elements("css selector", "section.route tr[data-outcome]")
                if r.is_displayed()]
        assert rows and all(r.get_attribute("data-outcome") == "flipped" or
                            r.get_attribute("data-family") == "baseline" for r in rows)
        driver.execute_script("var s=document.getElementById('f-agent');s.value='route-oracle';"
                              "s.dispatchEvent(new Event('change'));")
        assert driver.find_element("id", "shown").text == "0"  # the oracle ignores the text: no flip
        clips = driver.find_elements("css selector", ".clip img")
        assert clips, "a flipped episode shows its divergence clip"
        first = clips[1].get_attribute("src")
        time.sleep(1.2)
        assert clips[1].get_attribute("src") != first  # the clip plays
        severe = [e for e in driver.get_log("browser") if e["level"] == "SEVERE"]
        assert severe == []
    finally:
        driver.quit()


def test_episodes_csv_and_attribution_say_where_when_and_what(report):
    import csv

    out = report.parent
    rows = list(csv.DictReader((out / "episodes.csv").open(encoding="utf-8")))
    assert len(rows) == 2 * 2 * 3  # agents x routes x (baseline + 2 variants)
    for r in rows:
        assert float(r["end_t"]) > 0 and float(r["end_pos"]) <= float(r["length"]) + 1
        assert r["outside_lanes_pct"] != "" and r["instructions"]
        assert r["instructions"].startswith("baseline" if r["family"] == "baseline" else "M.")
    flips = [r for r in rows if r["agent"] == "instruction-follower" and r["family"] == "misleading"
             and r["termination_class"] != "done"]
    md = (out / "attribution.md").read_text(encoding="utf-8")
    assert flips and md.count("| instruction-follower | tiny_0") == len(flips)
