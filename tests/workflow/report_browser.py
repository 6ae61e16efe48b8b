"""The Snakemake report opened in a real headless browser: Debian's Chromium driven by Selenium
through Debian's chromedriver (nothing is downloaded at run time).

Snakemake 9 writes `--report report.html` as one self-contained page: a React app whose results
are a JavaScript object `results` (path -> name, labels, mime type and the file itself as a
data: URI), shown in an <img> (images) or an <iframe> (HTML) when chosen. So the check loads the
page, waits for the app, then, in the page, decodes every image as the report's <img> would
(naturalWidth > 0) and parses every HTML result as its frame would (every <table> has body rows),
and asks that each expected figure is there.
"""

from __future__ import annotations

import shutil
from pathlib import Path

CHROMIUM = shutil.which("chromium") or "/usr/bin/chromium"
CHROMEDRIVER = shutil.which("chromedriver") or "/usr/bin/chromedriver"
LOAD_TIMEOUT_S = 60

_IMAGE_WIDTHS = """
const uris = arguments[0], done = arguments[arguments.length - 1];
Promise.all(uris.map(uri => new Promise(resolve => {
  const img = document.createElement("img");
  img.onload = () => resolve(img.naturalWidth);
  img.onerror = () => resolve(0);
  img.src = uri;
  document.body.appendChild(img);
}))).then(done);
"""
_TABLE_ROWS = """
const uris = arguments[0], done = arguments[arguments.length - 1];
Promise.all(uris.map(uri => fetch(uri).then(r => r.text()).then(text => {
  const doc = new DOMParser().parseFromString(text, "text/html");
  return Array.from(doc.querySelectorAll("table")).map(t => t.querySelectorAll("tbody tr").length);
}).catch(() => null))).then(done);
"""


def browser():
    from selenium import webdriver
    from selenium.webdriver.chrome.options import Options
    from selenium.webdriver.chrome.service import Service

    options = Options()
    options.binary_location = CHROMIUM
    options.set_capability("goog:loggingPrefs", {"browser": "SEVERE"})
    for argument in ("--headless=new", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage"):
        options.add_argument(argument)
    return webdriver.Chrome(service=Service(CHROMEDRIVER), options=options)


def report_problems(report: Path, expected: dict[str, set[str]]) -> list[str]:
    """What is wrong with the report at ``report``, as lines (none: it is whole): the app did not
    load, an image does not decode, an HTML result has a table without rows (or no table), or
    a file of ``expected`` (scene -> file names) is not among the scene's results."""
    from selenium.webdriver.support.ui import WebDriverWait

    driver = browser()
    try:
        driver.set_script_timeout(LOAD_TIMEOUT_S)
        driver.get(Path(report).resolve().as_uri())
        WebDriverWait(driver, LOAD_TIMEOUT_S).until(
            lambda d: d.execute_script("return document.querySelector('#app').childElementCount > 0")
        )
        problems = []
        errors = [e for e in driver.get_log("browser") if e.get("level") == "SEVERE"]
        problems += [f"console error: {e['message'][:200]}" for e in errors]
        results = driver.execute_script("return results;")
        images = {path: r for path, r in results.items() if r["mime_type"].startswith("image/")}
        pages = {path: r for path, r in results.items() if r["mime_type"] == "text/html"}
        if not images or not pages:
            problems.append(f"{len(images)} images and {len(pages)} HTML results: expected some of both")
        widths = driver.execute_async_script(_IMAGE_WIDTHS, [r["data_uri"] for r in images.values()])
        problems += [f"image does not load: {path}" for path, width in zip(images, widths) if not width]
        tables = driver.execute_async_script(_TABLE_ROWS, [r["data_uri"] for r in pages.values()])
        for path, rows in zip(pages, tables):
            if not rows:
                problems.append(f"no table in {path}")
            elif min(rows) == 0:
                problems.append(f"a table without rows in {path}")
    finally:
        driver.quit()
    for scene, names in expected.items():
        present = {Path(path).name for path in results if f"results/{scene}/" in path}
        problems += [f"missing from the report: results/{scene}/.../{name}" for name in sorted(names - present)]
    return problems


def edit_results(report: Path, out: Path, edit) -> Path:
    """A copy of the report whose `results` object ``edit`` changed (a dict -> None)."""
    import json

    text = Path(report).read_text()
    block = text.index('<script id="results">')  # the report's own; its libraries have a `var results` too
    start = text.index("var results = ", block) + len("var results = ")
    end = text.index(";\n", start)
    results = json.loads(text[start:end])
    edit(results)
    Path(out).write_text(text[:start] + json.dumps(results) + text[end:])
    return Path(out)
