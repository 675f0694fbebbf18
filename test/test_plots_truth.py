"""The figures are right: what each plotting function drew, read back from the figure's
artists, against closed forms and independent computations (numpy, scipy), on models and
signals whose answers are known. Also the PNG writer and the progress bar."""

from __future__ import annotations

import io
import struct
import zlib
from pathlib import Path

import numpy as np
import pytest
from scipy import optimize, signal

from pmsm_sysid import plots
from pmsm_sysid.core.frequency.analysis import analyse
from pmsm_sysid.core.frequency.gfrf import Gfrf
from pmsm_sysid.core.terms.model import NarxModel
from pmsm_sysid.core.validation.correlation import correlation_tests
from pmsm_sysid.progress import Bar, activity, progress, silence

# A resonant linear part: poles r e^{+-j 2 pi F0} -> y(k) = a1 y(k-1) + a2 y(k-2) + ...
R, F0 = 0.95, 0.06
A1, A2 = 2 * R * np.cos(2 * np.pi * F0), -R * R
B, C, G = 0.8, 0.3, 0.05


def _denominator(f: np.ndarray) -> np.ndarray:
    z = np.exp(-2j * np.pi * f)
    return 1 - A1 * z - A2 * z * z


def _resonance() -> float:
    """Where |1 - a1 z - a2 z^2| is smallest on the unit circle (closed-form polynomial)."""
    res = optimize.minimize_scalar(lambda f: abs(_denominator(np.array(f))),
                                   bounds=(0.0, 0.5), method="bounded",
                                   options={"xatol": 1e-10})
    return float(res.x)


def _model(**extra: float) -> NarxModel:
    terms = {"y(k-1)": A1, "y(k-2)": A2, "u(k-1)": B, **extra}
    return NarxModel.from_terms(terms, sample_rate_hz=500.0)


def _png_header(path: Path) -> tuple[int, int]:
    raw = path.read_bytes()
    assert raw[:8] == b"\x89PNG\r\n\x1a\n"
    length, ctype = struct.unpack(">I4s", raw[8:16])
    assert ctype == b"IHDR" and length == 13
    body = raw[16:29]
    (crc,) = struct.unpack(">I", raw[29:33])
    assert zlib.crc32(raw[12:29]) == crc
    w, h = struct.unpack(">II", body[:8])
    assert raw.rstrip(b"\x00").endswith(b"IEND\xaeB`\x82")
    return w, h


def _line_constant(kind: str, x: np.ndarray, y: np.ndarray) -> float:
    """c of the drawn segment a*x + b*y = c, checking it is one straight line."""
    a, b = plots.RIDGE_LINES[kind]
    c = a * x + b * y
    assert np.ptp(c) < 1e-12
    return float(c[0])


# --- correlation tests: band = 1.96/sqrt(N), values = independent correlations ---------

def _phi(a: np.ndarray, b: np.ndarray, tau: int) -> float:
    """phi_ab(tau) = sum a(k) b(k+tau) / sqrt(sum a^2 sum b^2), with np.correlate."""
    full = np.correlate(b, a, mode="full")  # index n-1+tau holds sum a(k) b(k+tau)
    return float(full[len(a) - 1 + tau] / np.sqrt(np.dot(a, a) * np.dot(b, b)))


@pytest.mark.parametrize("n", [400, 1002])
def test_correlation_figure_band_and_values(n: int) -> None:
    rng = np.random.default_rng(n)
    u = rng.standard_normal(n)
    e = rng.standard_normal(n) + 0.3 * np.roll(u, 2)  # some correlation to draw
    tests = correlation_tests(e, u, max_lag=20)
    data = plots.correlation_tests(tests, n).data
    band = 1.96 / np.sqrt(n)
    ec, uc = e - e.mean(), u - u.mean()
    u2 = u * u - np.mean(u * u)
    e2 = e * e - np.mean(e * e)
    for name in ("ee", "ue", "u2e", "u2e2", "e_eu"):
        assert data[name]["band_upper"] == pytest.approx(band, rel=1e-12)
        assert data[name]["band_lower"] == pytest.approx(-band, rel=1e-12)
    for tau, v in zip(data["ee"]["lags"], data["ee"]["values"], strict=True):
        assert v == pytest.approx(_phi(ec, ec, int(tau)), abs=1e-12)
    for tau, v in zip(data["ue"]["lags"], data["ue"]["values"], strict=True):
        assert v == pytest.approx(_phi(uc, ec, int(tau)), abs=1e-12)
    for tau, v in zip(data["u2e2"]["lags"], data["u2e2"]["values"], strict=True):
        assert v == pytest.approx(_phi(u2, e2, int(tau)), abs=1e-12)
    # the planted correlation e ~ u(k-2) is what the ue panel shows largest, at tau = +2
    k = int(np.argmax(np.abs(data["ue"]["values"])))
    assert data["ue"]["lags"][k] == 2 and data["ue"]["values"][k] > 3 * band
    assert not data["ue"]["passed"]


# --- GFRF figures against closed forms -------------------------------------------------

def test_h1_figure_is_the_closed_form() -> None:
    model = _model(**{"u(k-1)^2": C})
    f, h = Gfrf.from_model(model).h1_curve(1025)
    data = plots.h1_gain_phase(f, h, 500.0).data
    z = np.exp(-2j * np.pi * data["f_norm"])
    h_true = B * z / _denominator(data["f_norm"])
    np.testing.assert_allclose(data["gain_db"], 20 * np.log10(np.abs(h_true)), atol=1e-9)
    dphi = np.angle(np.exp(1j * np.radians(data["phase_deg"] - np.degrees(np.angle(h_true)))))
    assert np.max(np.abs(dphi)) < 1e-9
    # the peak the analysis marks is the resonance of the closed form
    peaks = analyse(model).peaks
    marked = plots.h1_gain_phase(f, h, 500.0, peaks).data["peaks"]
    top = max(marked, key=lambda p: p[1])
    assert top[0] == pytest.approx(_resonance(), abs=2e-4)


def test_h2_contour_ridge_is_the_resonance_line() -> None:
    """H2 = c z12 / (1 - a1 z12 - a2 z12^2) depends on f1 + f2 only: its one ridge family
    is f1 + f2 = +-f_r with f_r the closed-form resonance; the contour is that closed form."""
    model = _model(**{"u(k-1)^2": C})
    an = analyse(model)
    ridges = an.h2["ridges"]
    f, h2 = Gfrf.from_model(model).h2_grid(201, 0.2)
    data = plots.h2_contour(f, h2, 500.0, ridges).data
    f_r = _resonance()
    drawn = data["ridges"]
    assert {d["kind"] for d in drawn} == {"f1+f2"}
    consts = sorted(_line_constant(d["kind"], d["x"], d["y"]) for d in drawn)
    assert consts == pytest.approx([-f_r, f_r], abs=5e-4)
    for d in drawn:  # each drawn line is the ridge the analysis reported
        assert _line_constant(d["kind"], d["x"], d["y"]) == pytest.approx(
            d["sign"] * d["freq_norm"], abs=1e-12)
    # the contoured array is 20 log10 |closed form| (rows f2, columns f1)
    x, y = np.meshgrid(f, f)
    z12 = np.exp(-2j * np.pi * (x + y))
    h_true = C * z12 / _denominator(x + y)
    np.testing.assert_allclose(data["db"], 20 * np.log10(np.abs(h_true)), atol=1e-9)
    # and its maximum lies on a drawn ridge line
    iy, ix = np.unravel_index(int(np.argmax(data["db"])), data["db"].shape)
    assert abs(abs(f[ix] + f[iy]) - f_r) <= 2 * (f[1] - f[0])


def test_h3_slice_ridge_is_the_resonance_line() -> None:
    """With a cubic input term and no other nonlinearity, H3 = g z123 / D(f1+f2+f3): on the
    slice f1 = f3 it depends on 2 f1 + f2, so the ridge is 2x + y = +-f_r."""
    model = _model(**{"u(k-1)^3": G})
    an = analyse(model)
    f, h3 = Gfrf.from_model(model).h3_slice(161, 0.2)
    data = plots.h3_slice(f, h3, 500.0, an.h3["ridges"]).data
    f_r = _resonance()
    drawn = [d for d in data["ridges"] if d["dominant"]]
    assert {d["kind"] for d in drawn} == {"f1+f2+f3"}
    consts = sorted(_line_constant(d["kind"], d["x"], d["y"]) for d in drawn)
    assert consts == pytest.approx([-f_r, f_r], abs=5e-4)
    x, y = np.meshgrid(f, f)  # x = f1 = f3 (columns), y = f2 (rows)
    s = 2 * x + y
    h_true = G * np.exp(-2j * np.pi * s) / _denominator(s)
    np.testing.assert_allclose(data["db"], 20 * np.log10(np.abs(h_true)), atol=1e-9)


def test_ridge_segments_stay_in_view_and_on_their_line() -> None:
    for kind in plots.RIDGE_LINES:
        for c in np.linspace(-0.6, 0.6, 25) + 0.0013:  # no c exactly on a corner
            seg = plots.gfrf.segment(kind, float(c), 0.25)
            a, b = plots.RIDGE_LINES[kind]
            reachable = abs(c) <= 0.25 * (abs(a) + abs(b))
            assert (seg is not None) == reachable, (kind, c)
            if seg is not None:
                x, y = seg
                assert np.all(np.abs(x) <= 0.25 + 1e-12) and np.all(np.abs(y) <= 0.25 + 1e-12)
                assert np.allclose(a * x + b * y, c, atol=1e-12)


# --- time-domain figures ---------------------------------------------------------------

def test_psd_figure_peaks_at_the_tone() -> None:
    fs, n = 500.0, 2000
    rng = np.random.default_rng(3)
    k = np.arange(n)
    u = 50 * np.sin(2 * np.pi * 16.5 / fs * k)
    y = 0.2 * np.sin(2 * np.pi * 16.5 / fs * k - 1.0) + 1e-3 * rng.standard_normal(n)
    fu, pu = signal.welch(u, fs=fs, nperseg=512, detrend="constant")
    _, py = signal.welch(y, fs=fs, nperseg=512, detrend="constant")
    data = plots.psd_pair(fu / fs, pu, py, fs).data
    assert data["peak_u_norm"] * fs == pytest.approx(16.5, abs=fs / 512)
    assert data["peak_y_norm"] * fs == pytest.approx(16.5, abs=fs / 512)
    np.testing.assert_allclose(data["psd_u"], np.maximum(pu, 1e-300))


def test_predicted_figure_reports_the_nmse_it_draws() -> None:
    k = np.arange(100, 300)
    y = np.sin(k / 7.0)
    yhat = y + 0.1 * np.cos(k / 3.0)
    data = plots.predicted_vs_measured(k, y, yhat, window="validation").data
    want = np.sum((y - yhat) ** 2) / np.sum((y - y.mean()) ** 2)
    assert data["nmse"] == pytest.approx(want, rel=1e-12)
    np.testing.assert_array_equal(data["predicted"], yhat)
    diverged = yhat.copy()
    diverged[150:] = np.nan  # a free run that diverged at k = 250
    bad = plots.predicted_vs_measured(k, y, diverged, window="validation")
    assert bad.data["nmse"] == float("inf") and "diverged at sample 250" in bad.caption
    io_data = plots.io_series(k, 2 * y, y).data
    np.testing.assert_array_equal(io_data["u"], 2 * y)


def test_view_covers_the_features() -> None:
    assert plots.view_fmax([0.033]) == 0.075
    assert plots.view_fmax([0.0026, 0.05]) == 0.1
    assert plots.view_fmax([0.4]) == 0.5
    assert plots.view_fmax([]) == 0.4


# --- PNG files -------------------------------------------------------------------------

def test_saved_png_is_valid_and_sized(tmp_path: Path) -> None:
    k = np.arange(50)
    plot = plots.io_series(k, k * 1.0, k * 2.0)
    path = plots.save(plot, tmp_path)
    assert path.name == "io_series.png"
    assert _png_header(path) == (800, 460)  # 8.0 x 4.6 in at 100 dpi
    from matplotlib import image

    px = image.imread(path)
    assert px.shape[:2] == (460, 800) and px.std() > 0.05  # decodes, not blank



def test_palette_keeps_the_background_and_up_to_255_colours_exactly() -> None:
    from pmsm_sysid.plots.base import palette_image

    rng = np.random.default_rng(3)
    rgba = np.full((40, 60, 4), 255, dtype=np.uint8)
    ink = rng.integers(0, 255, size=(255, 3), dtype=np.uint8)  # 255 colours, none white
    rgba.reshape(-1, 4)[:255 * 4, :3] = np.repeat(ink, 4, axis=0)
    image = palette_image(rgba)
    assert image.mode == "P" and len(image.getpalette() or []) <= 3 * 256
    np.testing.assert_array_equal(np.asarray(image.convert("RGB")), rgba[..., :3])
    blank = palette_image(np.full((5, 7, 4), 200, dtype=np.uint8))  # nothing drawn
    assert (np.asarray(blank.convert("RGB")) == 200).all()


def test_palette_figure_is_its_full_colour_image_but_for_rare_edge_pixels() -> None:
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    from pmsm_sysid.plots.base import palette_image

    k = np.arange(2000)
    figure = plots.psd_pair(k / 4000, 1 + np.cos(k / 50) ** 2, 1 + np.sin(k / 30) ** 2,
                            1000.0).figure
    canvas = FigureCanvasAgg(figure)
    canvas.draw()
    rgba = np.asarray(canvas.buffer_rgba())
    got = np.asarray(palette_image(rgba).convert("RGB")).astype(int)
    err = np.abs(got - rgba[..., :3]).max(axis=-1)
    white = (rgba[..., :3] == 255).all(axis=-1)
    assert not err[white].any()  # the background exactly
    assert (err > 0).mean() < 0.03 and err.mean() < 0.2


# --- progress bars ---------------------------------------------------------------------

def test_progress_is_silent_off_a_terminal(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("PMSM_SYSID_PROGRESS", raising=False)
    out = io.StringIO()  # not a TTY
    assert list(progress(range(5), label="x", stream=out)) == [0, 1, 2, 3, 4]
    assert out.getvalue() == ""


def test_progress_draws_when_forced(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("PMSM_SYSID_PROGRESS", "1")
    out = io.StringIO()
    assert sum(progress(range(4), label="grid", stream=out)) == 6
    text = out.getvalue()
    assert "grid" in text and "100%" in text and "4/4" in text and "\n" in text
    monkeypatch.setenv("PMSM_SYSID_PROGRESS", "0")
    out2 = io.StringIO()
    with Bar(3, "x", stream=out2) as bar:
        bar.update(3)
    assert out2.getvalue() == ""


class _Tty(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_progress_follows_the_terminal_and_quiet(monkeypatch: pytest.MonkeyPatch) -> None:
    """Drawn (by rich) on a terminal; --quiet (silence) turns it off there too."""
    monkeypatch.delenv("PMSM_SYSID_PROGRESS", raising=False)
    out = _Tty()
    list(progress(iter(range(3)), total=3, label="bag", stream=out))
    assert "3/3" in out.getvalue() and "bag" in out.getvalue()
    out = _Tty()
    with activity("identify", stream=out) as say:
        say("fitting")
    assert "identify: fitting" in out.getvalue()
    try:
        silence()
        quiet = _Tty()
        list(progress(range(3), label="bag", stream=quiet))
        with activity("identify", stream=quiet):
            pass
        assert quiet.getvalue() == ""
    finally:
        silence(False)


def test_core_never_imports_matplotlib() -> None:
    """Plotting lives outside the numerical core: importing every core module loads
    neither matplotlib nor Pillow."""
    import subprocess
    import sys

    code = (
        "import importlib, pkgutil, sys\n"
        "import pmsm_sysid.core as core\n"
        "for m in pkgutil.walk_packages(core.__path__, 'pmsm_sysid.core.'):\n"
        "    importlib.import_module(m.name)\n"
        "bad = sorted(n for n in sys.modules if n.split('.')[0] in ('matplotlib', 'PIL'))\n"
        "print(len(list(pkgutil.walk_packages(core.__path__, 'pmsm_sysid.core.'))), bad)\n"
    )
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                       timeout=120)
    assert r.returncode == 0, r.stderr
    n, bad = r.stdout.split(" ", 1)
    assert int(n) > 20 and bad.strip() == "[]", r.stdout


def test_a_verbs_quiet_lasts_as_long_as_the_verb(tmp_path: Path,
                                                monkeypatch: pytest.MonkeyPatch) -> None:
    """``main([..., '--quiet'])`` called in-process silences the bars for that call only:
    the caller's bars draw again afterwards."""
    from pmsm_sysid.cli import main

    monkeypatch.delenv("PMSM_SYSID_PROGRESS", raising=False)
    assert main(["identify", str(tmp_path / "missing_bag"), "--quiet"]) == 2
    out = _Tty()
    list(progress(iter(range(3)), total=3, label="bag", stream=out))
    assert "3/3" in out.getvalue()
