"""The report page in a real browser: headless Chromium (Debian package ``chromium``) loads
``index.html`` alone -- copied into an empty directory, so the PNGs beside it cannot be
used, and with the network switched off -- every embedded image loads (naturalWidth/Height
equal the PNG's), and in a full-page screenshot each image's box shows that figure (pixel
correlation with the PNG).

Chromium comes from the set-up (``make browser``, part of ``make test``), through the
``chromium`` fixture of conftest.py: where the set-up could not install it (not root, no
apt-get) the tests are skipped with that reason; where it promised one, they fail without it.
"""

from __future__ import annotations

import html
import json
import re
import shutil
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from conftest import Chromium
from test_report import FIGURES, REPO, bundled_bag, check_page, cli, png_size

CHECK_JS = """<script>
window.addEventListener('load', function () {
  var rows = Array.prototype.map.call(document.images, function (i) {
    var r = i.getBoundingClientRect();
    return {src: i.getAttribute('data-file'), complete: i.complete, w: i.naturalWidth,
            h: i.naturalHeight, x: r.left + window.scrollX, y: r.top + window.scrollY,
            dw: r.width, dh: r.height};
  });
  var pre = document.createElement('pre');
  pre.id = 'imgcheck';
  pre.textContent = JSON.stringify({images: rows,
                                    height: document.documentElement.scrollHeight});
  document.body.appendChild(pre);
});
</script>"""


def _image_rows(chromium: Chromium, index: Path, tmp: Path) -> dict[str, Any]:
    """Load a copy of the page with a checking script; return what it wrote to the DOM."""
    check = index.parent / "_check.html"
    check.write_text(index.read_text(encoding="utf-8").replace("</body>", CHECK_JS + "</body>"),
                     encoding="utf-8")
    r = chromium.run(check.as_uri(), tmp / "profile", "--window-size=1100,900", "--dump-dom")
    m = re.search(r'<pre id="imgcheck">(.*?)</pre>', r.stdout, re.S)
    assert m, f"the page's check did not run (rc {r.returncode}): {r.stderr[-500:]}"
    check.unlink()
    rows: dict[str, Any] = json.loads(html.unescape(m.group(1)))
    return rows


def _grey(img: Any, size: tuple[int, int] = (160, 120)) -> np.ndarray:
    from PIL import Image

    g = np.asarray(img.convert("L").resize(size, Image.Resampling.BOX), dtype=np.float64)
    return g.ravel()


def _check_in_browser(chromium: Chromium, out: Path, figures: set[str],
                      tmp_path: Path) -> None:
    """The page ``out/index.html``, alone in an empty directory, in headless Chromium."""
    from PIL import Image

    check_page(out / "index.html", figures)
    alone = tmp_path / "mailed"  # the page on its own, as a mail attachment would be
    alone.mkdir()
    index = Path(shutil.copy(out / "index.html", alone))

    rows = _image_rows(chromium, index, tmp_path)
    images = rows["images"]
    assert sorted(i["src"] for i in images) == sorted(f"{n}.png" for n in figures)
    assert sorted(p.name for p in alone.iterdir()) == ["index.html"]
    for i in images:
        w, h = png_size(out / i["src"])
        assert i["complete"] and (i["w"], i["h"]) == (w, h), i  # loaded, the right file

    shot = tmp_path / "shot.png"
    height = int(rows["height"])
    chromium.run(index.as_uri(), tmp_path / "profile", f"--window-size=1100,{height}",
                 f"--screenshot={shot}")
    assert shot.is_file(), "chromium wrote no screenshot"
    figs = {}
    for i in images:
        with Image.open(out / i["src"]) as fig:
            figs[i["src"]] = _grey(fig)
    with Image.open(shot) as page:
        assert page.size == (1100, height)
        for i in images:
            x, y = round(i["x"]) + 1, round(i["y"]) + 1  # inside the 1 px border
            seen = _grey(page.crop((x, y, x + round(i["dw"]) - 2, y + round(i["dh"]) - 2)))
            assert np.std(seen) > 5, f"{i['src']}: blank where the figure should be"
            corr = {src: float(np.corrcoef(seen, g)[0, 1]) for src, g in figs.items()}
            best = max(corr, key=lambda src: corr[src])
            # the box shows this figure (displayed at its natural size: nearly pixel-equal),
            # and it resembles no other figure as much
            assert best == i["src"] and corr[best] > 0.98, (i["src"], corr)


@pytest.mark.slow
def test_report_images_load_in_headless_chromium(chromium: Chromium, tmp_path: Path) -> None:
    out = tmp_path / "report"
    r = cli("report", str(bundled_bag()), "--out", str(out))
    assert r.returncode == 0, r.stderr
    _check_in_browser(chromium, out, FIGURES, tmp_path)


@pytest.mark.slow
def test_diagnose_report_loads_in_headless_chromium(chromium: Chromium,
                                                    tmp_path: Path) -> None:
    """diagnose --report: the common figures and one before/after figure per named effect."""
    out = tmp_path / "report"
    r = cli("diagnose", "--plant", str(REPO / "plants" / "nominal.yaml"), "--real",
            str(REPO / "bags" / "concealed_two"), "--validate",
            str(REPO / "bags" / "concealed_two_validate"), "--no-gfrf", "--report", str(out))
    assert r.returncode == 0, r.stderr
    figures = {"diagnose_fit", "diagnose_residual_time", "diagnose_residual_vs_position",
               "diagnose_residual_vs_velocity", "diagnose_speed_replay",
               "effect_coulomb_friction", "effect_cogging"}
    _check_in_browser(chromium, out, figures, tmp_path)
