"""Screenshots of the built site in headless Chromium, checked to show content.

Run after ``make docs``: ``python docs/screenshot.py [--out docs/_build/screenshots]``. Takes the
landing page, the getting-started page, the gallery and the ``sparse_attack_v0`` page, and fails
unless each picture has enough non-background pixels to be a rendered page (an empty or unstyled
page fails). Needs Debian's ``chromium``.
"""

from __future__ import annotations

import argparse
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
from matplotlib.image import imread

HTML = Path(__file__).resolve().parent / "_build" / "html"
PAGES = {
    "index": "index.html",
    "getting_started": "getting_started.html",
    "gallery": "environments/gallery.html",
    "sparse_attack_v0": "environments/sparse_attack_v0.html",
}
FLAGS = [
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--hide-scrollbars",
    "--window-size=1280,1600",
]


def screenshot(page: Path, out: Path, browser: str) -> np.ndarray:
    """Render ``page`` to ``out`` (PNG) and return the image."""
    with tempfile.TemporaryDirectory() as profile:
        subprocess.run(
            [browser, *FLAGS, f"--user-data-dir={profile}", f"--screenshot={out}", page.as_uri()],
            check=True,
            capture_output=True,
            timeout=120,
        )
    return imread(out)


def content_fraction(image: np.ndarray) -> float:
    """Fraction of pixels that differ from the most common colour (the background)."""
    rgb = (image[..., :3] * 255).astype(np.int32)
    codes = (rgb[..., 0] << 16) | (rgb[..., 1] << 8) | rgb[..., 2]
    _, counts = np.unique(codes, return_counts=True)
    return float(1.0 - counts.max() / codes.size)


def main(argv: list[str] | None = None) -> int:
    """Take the screenshots; exit 1 if a page looks empty."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=HTML.parent / "screenshots")
    args = parser.parse_args(argv)
    browser = shutil.which("chromium") or shutil.which("chromium-browser")
    if browser is None:
        print("chromium not found: apt-get install chromium", file=sys.stderr)
        return 2
    args.out.mkdir(parents=True, exist_ok=True)
    status = 0
    for name, rel in PAGES.items():
        image = screenshot(HTML / rel, args.out / f"{name}.png", browser)
        fraction = content_fraction(image)
        ok = fraction > 0.02
        status |= not ok
        print(
            f"{name}: {args.out / f'{name}.png'} {image.shape[1]}x{image.shape[0]}, "
            f"{fraction:.1%} content pixels {'ok' if ok else 'EMPTY?'}"
        )
    return status


if __name__ == "__main__":
    raise SystemExit(main())
