"""Screenshots of a study's report.html in headless Chromium, to look at before a change
to the report lands (run on demand: ``python tests/benchmarks/report_screenshots.py
mdaug-study/report.html --out shots/``).

Writes, at a 1400-pixel-wide window:

* ``page.png``: the page as a reader first sees it (folded sections closed), cut to the
  page's length;
* ``expanded.png``: the same with every folded section open;
* ``page_NN.png`` / ``expanded_NN.png``: both cut into tiles of ``--tile`` pixels, a
  size an image viewer shows without shrinking the text.

Needs ``chromium`` (Debian: ``apt-get install chromium``), ``chromium-browser`` or
``google-chrome`` on the PATH, and Pillow (a matplotlib dependency). Exit status 2
when no browser is found.
"""
from __future__ import annotations

import argparse
import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

BROWSERS = ("chromium", "chromium-browser", "google-chrome")
FLAGS = ("--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
         "--disable-background-networking", "--disable-component-update", "--disable-sync",
         "--hide-scrollbars", "--mute-audio")


def find_browser() -> str | None:
    return next((shutil.which(b) for b in BROWSERS if shutil.which(b)), None)


def screenshot(browser: str, html: Path, png: Path, width: int, height: int, timeout: float = 120.0) -> Path:
    with tempfile.TemporaryDirectory() as profile:
        subprocess.run([browser, *FLAGS, f"--user-data-dir={profile}", f"--screenshot={png}",
                        f"--window-size={width},{height}", html.resolve().as_uri()],
                       check=True, capture_output=True, timeout=timeout)
    if not png.is_file():
        raise RuntimeError(f"{browser} wrote no screenshot of {html}")
    return png


def trim(png: Path, margin: int = 20) -> tuple[int, int]:
    """Cut the blank bottom of a screenshot (the window was taller than the page)."""
    from PIL import Image, ImageChops

    im = Image.open(png).convert("RGB")
    bg = Image.new("RGB", im.size, (255, 255, 255))
    box = ImageChops.difference(im, bg).getbbox()
    if box:
        im = im.crop((0, 0, im.size[0], min(box[3] + margin, im.size[1])))
    im.save(png)
    return im.size


def tiles(png: Path, tile: int) -> list[Path]:
    from PIL import Image

    im = Image.open(png)
    out = []
    for i, top in enumerate(range(0, im.size[1], tile)):
        p = png.with_name(f"{png.stem}_{i:02d}.png")
        im.crop((0, top, im.size[0], min(top + tile, im.size[1]))).save(p)
        out.append(p)
    return out


def expanded_copy(html: Path, folder: Path) -> Path:
    """The page with every <details> open (beside the original, so relative links work)."""
    text = re.sub(r"<details(?![^>]*\bopen\b)", "<details open", html.read_text())
    out = html.with_name(html.stem + ".expanded.html")
    out.write_text(text)
    return out


def shoot(html, out, width: int = 1400, max_height: int = 30000, tile: int = 1800) -> dict:
    """Screenshots of report ``html`` into folder ``out``: {name: (path, size, tiles)}."""
    browser = find_browser()
    if browser is None:
        raise FileNotFoundError(f"no headless browser found (tried {', '.join(BROWSERS)})")
    html, out = Path(html), Path(out)
    out.mkdir(parents=True, exist_ok=True)
    shots = {}
    expanded = expanded_copy(html, out)
    try:
        for name, page in (("page", html), ("expanded", expanded)):
            png = screenshot(browser, page, out / f"{name}.png", width, max_height)
            size = trim(png)
            shots[name] = (png, size, tiles(png, tile))
    finally:
        expanded.unlink(missing_ok=True)
    return shots


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description="Screenshots of a study report in headless Chromium.")
    ap.add_argument("report", help="report.html of a study")
    ap.add_argument("--out", default="report-screenshots", help="folder for the PNGs (default: %(default)s)")
    ap.add_argument("--width", type=int, default=1400, help="window width in pixels (default: %(default)s)")
    ap.add_argument("--max-height", type=int, default=30000, help="window height, pixels (default: %(default)s)")
    ap.add_argument("--tile", type=int, default=1800, help="tile height, pixels (default: %(default)s)")
    args = ap.parse_args(argv)
    try:
        shots = shoot(args.report, args.out, args.width, args.max_height, args.tile)
    except FileNotFoundError as exc:
        print(f"report_screenshots: {exc}", file=sys.stderr)
        return 2
    for name, (png, size, parts) in shots.items():
        print(f"{png}: {size[0]} x {size[1]} px, {len(parts)} tile(s)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
