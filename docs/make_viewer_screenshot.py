"""Write ``docs/viewer.png``: the page of the compact fit (``pj.fit_compact``, 33 numbers) against the neural MERL
fit it was fitted to.

    POLYJAX_DATA=<data root> PYTHONPATH=.:tests python docs/make_viewer_screenshot.py

Needs Chromium and ``websocket-client`` (the test extra); uses the tests' DevTools client (``tests/_browser.py``).
"""

import sys
import tempfile
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

from _browser import Browser, find_chromium  # noqa: E402
from PIL import Image  # noqa: E402 - matplotlib's own image library

import polyjax as pj  # noqa: E402

NAME = "gold-metallic-paint"


def main() -> int:
    data = pj.data.load_merl_nbrdf(NAME, subsample=20000, seed=0)
    fit = pj.fit_compact(data, 33)
    items = [(f"compact, {fit.n_numbers} numbers ({NAME})", fit),
             (f"neural MERL fit ({NAME})", pj.data.load_nbrdf(NAME))]
    out = Path(__file__).with_name("viewer.png")
    with tempfile.TemporaryDirectory() as tmp:
        page = pj.view.write_page(items, Path(tmp) / "page.html", settings=pj.view.ViewSettings(size=160))
        browser = Browser(find_chromium())
        try:
            browser.open(page.as_uri(), width=1180, height=620)
            assert browser.errors() == [], browser.errors()
            image = browser.screenshot()
        finally:
            browser.close()
    Image.fromarray(image).save(out, optimize=True)
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
