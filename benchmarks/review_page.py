"""How fast the review page of a prediction opens and redraws, in headless Chromium (issue 16).

    .venv/bin/python benchmarks/review_page.py PRED_DIR [--screenshot docs/review.png] [--bounds MINX,MINY,MAXX,MAXY --out DIR]

Writes PRED_DIR/review (or the page of one district, ``--bounds``, into ``--out``) with
``csboundary review`` if it is not there (timed), opens its
index.html from disk in Debian's Chromium (headless, 1400 x 900 window) and prints:

* **open**: from navigation start until the script has built the page and every image tile of
  the first (whole-city) view is drawn;
* **redraw**: the time of one full redraw (tiles + every edge) at the whole-city view, zoomed in 8x
  and 64x on the least sure boundary, the median of 20 each (``window.review.drawNow``);
* **select**: clicking the first row of the boundary list until the view is centred on it (at
  full resolution, ground truth shown).

``--screenshot`` saves the page with the least sure boundary selected (the README's picture).
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import time
from pathlib import Path


def browser():
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    options = webdriver.ChromeOptions()
    options.binary_location = "/usr/bin/chromium"
    for flag in (
        "--headless=new",
        "--no-sandbox",
        "--disable-background-networking",
        "--disable-gpu",
        "--window-size=1400,900",
    ):
        options.add_argument(flag)
    return webdriver.Chrome(service=Service("/usr/bin/chromedriver"), options=options)


def wait(driver, script: str, timeout: float = 60.0):
    deadline = time.time() + timeout
    while time.time() < deadline:
        value = driver.execute_script(script)
        if value:
            return value
        time.sleep(0.02)
    raise SystemExit(f"timed out waiting for {script}")


ALL_VISIBLE_TILES_DRAWN = """
const r = window.review; if (!r) return false;
return r.loadedTiles() > 0 && r.pendingTiles() === 0 && r.state.frames > 1;
"""


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("prediction", type=Path)
    parser.add_argument("--screenshot", type=Path)
    parser.add_argument("--bounds", help="one district: MINX,MINY,MAXX,MAXY in the prediction's CRS")
    parser.add_argument("--out", type=Path, help="the page's folder (default PRED_DIR/review)")
    args = parser.parse_args()
    folder = (args.out or args.prediction / "review").resolve()
    page = folder / "index.html"
    if not page.exists():
        start = time.perf_counter()
        district = ["--bounds", args.bounds] if args.bounds else []
        subprocess.run(
            [
                sys.executable,
                "-m",
                "csboundary",
                "review",
                str(args.prediction),
                "--out",
                str(folder),
                "--quiet",
                *district,
            ],
            check=True,
        )
        print(f"csboundary review: {time.perf_counter() - start:.1f} s")
    data = (folder / "data.js").read_text()
    meta = json.loads(data[data.index("=") + 1 : data.rindex(";")])
    tiles = sum(1 for _ in (folder / "tiles").rglob("*.jpg"))
    print(
        f"page of {meta['width']}x{meta['height']} px, "
        f"{len(meta['edges'])} edges in {len(meta.get('boundaries') or [])} boundaries, "
        f"{meta['levels']} pyramid levels, {tiles} tiles, "
        f"data.js {len(data) / 1e6:.1f} MB"
    )
    driver = browser()
    try:
        driver.get(page.as_uri())
        wait(driver, ALL_VISIBLE_TILES_DRAWN)
        opened = driver.execute_script("return performance.now()")
        print(
            f"open: {opened / 1000:.2f} s until the page is built and the first view's "
            f"{driver.execute_script('return window.review.loadedTiles()')} "
            "tiles are drawn"
        )
        first = "document.querySelector('#edge-list li:not([hidden])')"  # the least sure boundary of the draft
        lowest = int(driver.execute_script(f"return +{first}.dataset.boundary"))
        times = {}
        for name, factor in (("whole city", 1), ("zoom 8x", 8), ("zoom 64x", 64)):
            driver.execute_script("const r = window.review; r.select(null);")
            if factor > 1:
                driver.execute_script(f"""const r = window.review, e = REVIEW_DATA.edges[r.boundaries[{lowest}].edges[0]];
                    const p = e.line[Math.floor(e.line.length / 2)];
                    const c = document.getElementById('view'); r.state.scale = Math.min(c.width / REVIEW_DATA.width, c.height /
                    REVIEW_DATA.height) * {factor};
                    r.state.ox = p[0] - c.width / 2 / r.state.scale;
                    r.state.oy = p[1] - c.height / 2 / r.state.scale; r.render();""")
                time.sleep(0.5)  # let the tiles of that view load
            samples = driver.execute_script(
                "const r = window.review; return Array.from({length: 20}, () => r.drawNow());"
            )
            times[name] = statistics.median(samples)
        print("redraw (median of 20): " + ", ".join(f"{k} {v:.1f} ms" for k, v in times.items()))
        driver.execute_script("window.review.fit(); document.getElementById('show-gt').click();")
        start = time.perf_counter()
        driver.find_element("css selector", "#edge-list li:not([hidden])").click()
        wait(driver, f"return window.review.state.selected === {lowest}")
        print(
            f"select from the list: {1000 * (time.perf_counter() - start):.0f} ms (click to selection, through WebDriver)"
        )
        if args.screenshot:
            time.sleep(1.0)
            args.screenshot.parent.mkdir(parents=True, exist_ok=True)
            driver.save_screenshot(str(args.screenshot))
            print(f"screenshot: {args.screenshot}")
    finally:
        driver.quit()


if __name__ == "__main__":
    main()
