"""The report page in a real browser: headless Chromium (Debian package ``chromium``) loads
``index.html`` alone -- copied into an empty directory, so the PNGs beside it cannot be
used, and with the network switched off -- every embedded image loads (naturalWidth/Height
equal the PNG's), and in a full-page screenshot each image's box shows that figure (pixel
correlation with the PNG).

Chromium is installed by the fixture when it is missing and apt-get can run (as root);
otherwise the test is skipped with the reason.
"""

from __future__ import annotations

import html
import json
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from test_report import FIGURES, REPO, bundled_bag, check_page, png_size

NAMES = ("chromium", "chromium-browser")
APT_TIMEOUT_S = 900
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


def _which() -> str | None:
    return next((p for p in map(shutil.which, NAMES) if p), None)


def _apt(*args: str) -> subprocess.CompletedProcess[str]:
    env = {**os.environ, "DEBIAN_FRONTEND": "noninteractive"}
    return subprocess.run(["apt-get", "-o", "DPkg::Lock::Timeout=300", *args], env=env,
                          capture_output=True, text=True, timeout=APT_TIMEOUT_S)


@pytest.fixture(scope="session")
def chromium() -> str:
    """Path of the chromium binary; installs the Debian package when possible."""
    found = _which()
    if found:
        return found
    if shutil.which("apt-get") is None:
        pytest.skip("chromium is not installed and there is no apt-get to install it")
    if os.geteuid() != 0:
        pytest.skip("chromium is not installed and installing it needs root (apt-get)")
    try:
        r = _apt("install", "-y", "--no-install-recommends", "chromium")
        if r.returncode != 0:  # empty or stale package lists on a fresh machine
            _apt("update")
            r = _apt("install", "-y", "--no-install-recommends", "chromium")
    except subprocess.TimeoutExpired:
        pytest.skip(f"installing chromium took more than {APT_TIMEOUT_S} s")
    found = _which()
    if not found:
        tail = (r.stderr or r.stdout).strip().splitlines()[-1:] or ["no output"]
        pytest.skip(f"could not install chromium with apt-get: {tail[0]}")
    return found


def _run(exe: str, tmp: Path, url: str, *extra: str) -> subprocess.CompletedProcess[str]:
    args = [exe, "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic",
            "--no-first-run", "--disable-background-networking", "--disable-component-update",
            "--disable-sync", f"--user-data-dir={tmp / 'profile'}", "--hide-scrollbars",
            "--force-device-scale-factor=1", "--virtual-time-budget=10000",
            "--host-resolver-rules=MAP * ~NOTFOUND", "--proxy-server=127.0.0.1:9", *extra, url]
    return subprocess.run(args, capture_output=True, text=True, timeout=180)


def _image_rows(exe: str, index: Path, tmp: Path) -> dict[str, Any]:
    """Load a copy of the page with a checking script; return what it wrote to the DOM."""
    check = index.parent / "_check.html"
    check.write_text(index.read_text(encoding="utf-8").replace("</body>", CHECK_JS + "</body>"),
                     encoding="utf-8")
    r = _run(exe, tmp, check.as_uri(), "--window-size=1100,900", "--dump-dom")
    m = re.search(r'<pre id="imgcheck">(.*?)</pre>', r.stdout, re.S)
    assert m, f"the page's check did not run (rc {r.returncode}): {r.stderr[-500:]}"
    check.unlink()
    rows: dict[str, Any] = json.loads(html.unescape(m.group(1)))
    return rows


def _grey(img: Any, size: tuple[int, int] = (160, 120)) -> np.ndarray:
    from PIL import Image

    g = np.asarray(img.convert("L").resize(size, Image.Resampling.BOX), dtype=np.float64)
    return g.ravel()


def _check_in_browser(chromium: str, out: Path, figures: set[str], tmp_path: Path) -> None:
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
    _run(chromium, tmp_path, index.as_uri(), f"--window-size=1100,{height}",
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
@pytest.mark.timeout(APT_TIMEOUT_S * 2 + 300)
def test_report_images_load_in_headless_chromium(chromium: str, tmp_path: Path) -> None:
    out = tmp_path / "report"
    r = subprocess.run([sys.executable, "-m", "pmsm_sysid.cli", "report", str(bundled_bag()),
                        "--out", str(out)], capture_output=True, text=True, timeout=300,
                       cwd=REPO)
    assert r.returncode == 0, r.stderr
    _check_in_browser(chromium, out, FIGURES, tmp_path)


@pytest.mark.slow
@pytest.mark.timeout(APT_TIMEOUT_S * 2 + 300)
def test_diagnose_report_loads_in_headless_chromium(chromium: str, tmp_path: Path) -> None:
    """diagnose --report: the common figures and one before/after figure per named effect."""
    out = tmp_path / "report"
    r = subprocess.run([sys.executable, "-m", "pmsm_sysid.cli", "diagnose", "--plant",
                        str(REPO / "plants" / "nominal.yaml"), "--real",
                        str(REPO / "bags" / "concealed_two"), "--validate",
                        str(REPO / "bags" / "concealed_two_validate"), "--no-gfrf",
                        "--report", str(out)], capture_output=True, text=True, timeout=300,
                       cwd=REPO)
    assert r.returncode == 0, r.stderr
    figures = {"diagnose_fit", "diagnose_residual_time", "diagnose_residual_vs_position",
               "diagnose_residual_vs_velocity", "diagnose_speed_replay",
               "effect_coulomb_friction", "effect_cogging"}
    _check_in_browser(chromium, out, figures, tmp_path)
