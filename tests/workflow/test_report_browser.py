"""The Snakemake report of the smoke run, opened in a real headless browser.

``snakemake --report report.zip`` on the shared smoke run (conftest's ``smoke_results``); the
zip is unpacked and its ``report.html`` and the image viewer inside it are opened in Debian's
Chromium through chromedriver (selenium; Selenium Manager never downloads: both binaries are
given). Screenshots and the report's size and build time land in ``$MCBENCH_TEST_ARTIFACTS``
(default ``tests/artifacts/``). Without Chromium or chromedriver the browser tests are skipped,
except under CI (``$CI`` set), where a missing browser fails them.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import time
import zipfile
from pathlib import Path

import pytest

from tests.conftest import run_snakemake

pytestmark = pytest.mark.slow

REPO = Path(__file__).resolve().parents[2]
CHROMIUM_NAMES = ("chromium", "chromium-browser")
# the viewer's DOM contract: controls and displays the test relies on
VIEWER_CONTROLS = ("scene", "spp", "image-a", "image-b", "mode", "exposure", "flip")
VIEWER_DISPLAYS = ("view-a", "view-b", "numbers", "maps")


def artifacts_dir() -> Path:
    folder = Path(os.environ.get("MCBENCH_TEST_ARTIFACTS") or REPO / "tests" / "artifacts")
    folder.mkdir(parents=True, exist_ok=True)
    return folder


def _missing_browser(reason: str):
    if os.environ.get("CI"):
        pytest.fail(f"{reason} (required under CI; setup.sh installs Debian's chromium and chromium-driver as root)")
    pytest.skip(f"{reason}; install Debian's chromium and chromium-driver (setup.sh does, as root)")


@pytest.fixture(scope="module")
def report(smoke_results, tmp_path_factory):
    """The smoke run's report: ``{"html": path of report.html, "root": unpacked folder,
    "results": the report's result records, "categories": its categories, "seconds", "bytes"}``."""
    workdir, _ = smoke_results
    target = tmp_path_factory.mktemp("report")
    zip_path = target / "report.zip"
    start = time.perf_counter()
    run_snakemake(workdir, "--report", str(zip_path), timeout=600)
    seconds = time.perf_counter() - start
    with zipfile.ZipFile(zip_path) as archive:
        archive.extractall(target / "unpacked")
    html = target / "unpacked" / "report" / "report.html"
    assert html.is_file(), sorted(str(p) for p in (target / "unpacked").rglob("*"))[:20]
    text = html.read_text(encoding="utf-8")
    records = {}
    for name in ("results", "categories"):
        match = re.search(rf"^\s*var {name} = (\{{.*\}});\s*$", text, re.MULTILINE)
        assert match, f"no 'var {name} = {{...}}' in {html}"
        records[name] = json.loads(match.group(1))
    stats = {"report_zip_bytes": zip_path.stat().st_size, "report_seconds": round(seconds, 2),
             "unpacked_bytes": sum(p.stat().st_size for p in (target / "unpacked").rglob("*") if p.is_file())}
    (artifacts_dir() / "report_stats.json").write_text(json.dumps(stats, indent=2) + "\n")
    return {"html": html, "root": html.parent, **records, "seconds": seconds, "bytes": zip_path.stat().st_size}


@pytest.fixture(scope="module")
def browser():
    """Headless Chromium through chromedriver, logging the browser console."""
    try:
        from selenium import webdriver
        from selenium.webdriver.chrome.service import Service
    except ImportError:
        _missing_browser("selenium is not installed (pip install -e '.[test]')")
    chromium = next((path for path in map(shutil.which, CHROMIUM_NAMES) if path), None)
    driver_path = shutil.which("chromedriver")
    if not chromium or not driver_path:
        _missing_browser(f"no {'chromium' if not chromium else 'chromedriver'} on PATH")
    options = webdriver.ChromeOptions()
    options.binary_location = chromium
    for argument in ("--headless=new", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage",
                     "--window-size=1400,1000", "--allow-file-access-from-files"):
        options.add_argument(argument)
    options.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    driver = webdriver.Chrome(service=Service(executable_path=driver_path), options=options)
    driver.set_page_load_timeout(60)
    yield driver
    driver.quit()


def severe_console_messages(driver) -> list[str]:
    """The browser console's SEVERE entries since the last call (reading clears the log)."""
    return [entry["message"] for entry in driver.get_log("browser") if entry["level"] == "SEVERE"]


def screenshot(browser, name: str) -> None:
    """Save a screenshot to the artefacts folder, every panel scrolled to its top (the report
    scrolls its description panel on load)."""
    browser.execute_script("document.querySelectorAll('*').forEach(e => { e.scrollTop = 0; });")
    browser.save_screenshot(str(artifacts_dir() / name))


def wait_for(condition, *, timeout: float = 20.0, what: str):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        value = condition()
        if value:
            return value
        time.sleep(0.1)
    raise AssertionError(f"timed out after {timeout:.0f} s waiting for {what}")


def expected_items(config: dict) -> dict[str, dict]:
    """Report items a smoke run must have: path -> (category, subcategory, labels)."""
    items = {
        "results/metrics.csv": ("Data", "Errors", {"table": "metrics.csv"}),
        "results/timings.csv": ("Data", "Timings", {"table": "timings.csv"}),
        "results/manifest.json": ("Data", "Provenance", {"file": "manifest.json"}),
        "results/tables/scenes.csv": ("Scenes", "Scene table", {"table": "scenes"}),
        "results/figures/gallery.png": ("Scenes", "Gallery", {"figure": "references"}),
        "results/figures/speed_error.png": ("Figures", "Speed against error", {"metric": "relmse"}),
    }
    scene = config["scenes"][0]
    items[f"results/oracle/{scene}/table.csv"] = ("Figures", "Ground-truth statistics (Fig. 11)",
                                                  {"figure": "oracle table"})
    items[f"results/oracle/{scene}/weights.png"] = ("Figures", "Ground-truth statistics (Fig. 11)",
                                                    {"figure": "oracle weight maps"})
    items["results/tables/comparisons/ablations.csv"] = ("Comparisons", "Ablations", {"table": "ablations"})
    for metric in config["metrics"]:
        items[f"results/tables/comparisons/table1_{metric}.csv"] = (
            "Comparisons", "Tables 1-2: one-hot selection", {"metric": metric})
        items[f"results/tables/comparisons/ranking_{metric}.csv"] = (
            "Comparisons", "Comparison rankings", {"metric": metric})
        items[f"results/tables/ranking_{metric}.csv"] = ("Rankings", "Score-and-rank tables", {"metric": metric})
        items[f"results/figures/error_{metric}.png"] = ("Figures", "Error against spp", {"metric": metric})
    return items


def test_report_holds_every_table_and_figure_with_category_labels_and_caption(report, smoke_results):
    _, config = smoke_results
    results, categories = report["results"], report["categories"]
    placed = {path: (category, subcategory) for category, subcategories in categories.items()
              for subcategory, paths in subcategories.items() for path in paths}
    for path, (category, subcategory, labels) in expected_items(config).items():
        assert path in results, f"{path} is not a report item; items: {sorted(results)}"
        record = results[path]
        assert placed[path] == (category, subcategory), (path, placed[path])
        assert labels.items() <= record["labels"].items(), (path, record["labels"])
        assert all(isinstance(value, str) for value in record["labels"].values()), record["labels"]
        # a caption that says something, rendered from its .rst (not an empty default)
        assert len(re.sub(r"<[^>]+>", "", record["caption"]).split()) >= 20, (path, record["caption"])
        # in a zip report every item is a file of the archive
        assert (report["root"] / record["data_uri"]).is_file(), record["data_uri"]
    # within a subcategory the report keys items by their labels: equal labels would hide one
    for subcategories in categories.values():
        for paths in subcategories.values():
            keys = [json.dumps(results[path]["labels"], sort_keys=True) for path in paths]
            assert len(set(keys)) == len(keys), paths
    # the captions name the metric of their wildcard (Jinja in the .rst)
    assert "relMSE" in results["results/tables/ranking_relmse.csv"]["caption"]
    assert "DSSIM" in results["results/figures/error_dssim.png"]["caption"]
    # the workflow description names this run's scenes
    text = report["html"].read_text(encoding="utf-8")
    assert all(scene in text for scene in config["scenes"])


def open_category(browser, report, category: str, shows: str):
    """Load the report page, click ``category`` in its menu and wait until ``shows`` is displayed."""
    from selenium.webdriver.common.by import By

    browser.get(report["html"].as_uri())
    menu = wait_for(lambda: [e for e in browser.find_elements(By.XPATH, f"//*[normalize-space(text())='{category}']")
                             if e.is_displayed()], what=f"the report's {category} category in the menu")
    menu[0].click()
    wait_for(lambda: shows in browser.find_element(By.TAG_NAME, "body").text, what=f"{shows!r} in {category}")


def test_report_page_opens_without_console_errors(report, browser):
    browser.get(report["html"].as_uri())
    wait_for(lambda: "Ensemble Denoising" in browser.execute_script("return document.body.textContent"),
             what="the workflow description")
    # the top of the description is on screen (the template centres it in a fixed-height panel)
    top = browser.execute_script("const e = [...document.querySelectorAll('strong')]"
                                 ".find(e => e.textContent === 'This run'); return e && e.getBoundingClientRect().top;")
    assert top is not None and 0 <= top < 400, top
    screenshot(browser, "report.png")
    # a category with one subcategory lists its items by their labels
    open_category(browser, report, "Rankings", "relmse score and rank per spp")
    screenshot(browser, "report_rankings.png")
    # one with two shows both subcategories
    open_category(browser, report, "Figures", "Speed against error")
    assert "Error against spp" in browser.find_element("tag name", "body").text
    screenshot(browser, "report_figures.png")
    assert severe_console_messages(browser) == []


def viewer_index(report) -> Path:
    """The viewer's index.html inside the unpacked report (the report item of ``viewer``)."""
    for path, record in report["results"].items():
        if record["job_properties"]["rule"] == "viewer" and record["mime_type"] == "text/html":
            return report["root"] / record["data_uri"]
    raise AssertionError(f"no viewer item in the report; items: {sorted(report['results'])}")


def test_viewer_in_the_report_switches_candidates(report, browser):
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support.ui import Select

    index = viewer_index(report)
    assert (index.parent / "data.js").is_file(), sorted(p.name for p in index.parent.iterdir())
    browser.get(index.as_uri())
    wait_for(lambda: browser.execute_script("return !!window.MCBENCH_VIEWER"), what="the viewer's data.js")
    for name in VIEWER_CONTROLS + VIEWER_DISPLAYS:
        assert browser.find_elements(By.ID, name), f"viewer has no #{name}"
    image_a = Select(browser.find_element(By.ID, "image-a"))
    values = [option.get_attribute("value") for option in image_a.options]
    candidates = [value for value in values if value not in ("reference", "noisy")]
    assert {"reference", "noisy"} <= set(values) and len(candidates) >= 2, values
    view_a = browser.find_element(By.ID, "view-a")
    loaded = "return arguments[0].complete && arguments[0].naturalWidth > 0"
    previous = wait_for(lambda: view_a.get_attribute("src"), what="#view-a to show an image")
    shown = {}
    for value in candidates[:2]:
        if image_a.first_selected_option.get_attribute("value") == value:
            image_a.select_by_value("noisy")
            previous = wait_for(lambda: view_a.get_attribute("src") != previous and view_a.get_attribute("src"),
                                what="#view-a after choosing noisy")
        image_a.select_by_value(value)  # fires the select's change event
        previous = wait_for(lambda: view_a.get_attribute("src") != previous and view_a.get_attribute("src"),
                            what=f"#view-a to change after choosing {value}")
        wait_for(lambda: browser.execute_script(loaded, view_a), what=f"#view-a's image of {value} to load")
        shown[value] = previous
    assert shown[candidates[0]] != shown[candidates[1]], shown
    numbers = browser.find_element(By.ID, "numbers").text
    assert re.search(r"\d", numbers), f"#numbers shows no values: {numbers!r}"
    screenshot(browser, "viewer.png")

    # every other control changes without console errors
    Select(browser.find_element(By.ID, "mode")).select_by_value("slide")
    browser.execute_script("const e = document.getElementById('exposure'); e.value = 1;"
                           "e.dispatchEvent(new Event('input')); e.dispatchEvent(new Event('change'));")
    Select(browser.find_element(By.ID, "mode")).select_by_value("flip")
    browser.find_element(By.ID, "flip").click()
    spp = Select(browser.find_element(By.ID, "spp"))
    spp.select_by_index(len(spp.options) - 1)
    scene = Select(browser.find_element(By.ID, "scene"))
    scene.select_by_index(len(scene.options) - 1)
    wait_for(lambda: browser.execute_script(loaded, browser.find_element(By.ID, "view-a")),
             what="#view-a after the last change")
    screenshot(browser, "viewer_flip.png")
    assert severe_console_messages(browser) == []
