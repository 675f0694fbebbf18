"""What users read speaks plainly: no internal shorthand in the CLI help, the README, the docs
or the report page; the paper is cited by its authors and year; shaded "input has power"
regions of the H1 figure are where the estimation input has power."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
from scipy import signal

from pmsm_sysid.cli import build_parser
from pmsm_sysid.core.selection.identifiability import excitation_summary
from pmsm_sysid.plots.gfrf import h1_gain_phase
from pmsm_sysid.report.frequency import _excited

REPO = Path(__file__).resolve().parents[1]
# "seed" is fine as a random-number seed ("--seed N", "seed 1"); not as a name for the paper
SHORTHAND = re.compile(r"\bseed (?:Figs?\.|Tables?|Eqs?\.|§|paper)|\bseed's\b|[Cc]ontract|§"
                       r"|\bissue \d")


def _helps() -> dict[str, str]:
    parser = build_parser()
    out = {"pmsm-sysid": parser.format_help()}
    for action in parser._subparsers._group_actions:  # type: ignore[union-attr]
        for name, sub in action.choices.items():
            out[name] = sub.format_help()
    return out


def test_cli_help_has_no_shorthand() -> None:
    helps = _helps()
    assert len(helps) > 5
    for verb, text in helps.items():
        assert not SHORTHAND.search(text), (verb, SHORTHAND.search(text))


@pytest.mark.parametrize("path", sorted([REPO / "README.md", *(REPO / "docs").glob("*.md")]),
                         ids=lambda p: p.name)
def test_docs_have_no_shorthand(path: Path) -> None:
    text = path.read_text(encoding="utf-8")
    hits = [line for line in text.splitlines() if SHORTHAND.search(line)]
    assert not hits, hits[:3]


def test_readme_cites_the_paper_by_authors_and_year() -> None:
    text = (REPO / "README.md").read_text(encoding="utf-8")
    assert "Liu, Lee, Wang, Uppala & Chen (2005)" in text


def test_shaded_regions_are_where_the_input_has_power() -> None:
    """A two-tone input: one narrow shaded span per tone, holding nearly all the input power,
    and nothing shaded between the tones (where the input has no power)."""
    fs, n = 500.0, 20000
    k = np.arange(n)
    rng = np.random.default_rng(0)
    u = (40 * np.sin(2 * np.pi * 11.5 / fs * k) + 3 * np.cos(2 * np.pi * 0.5 / fs * k)
         + 0.01 * rng.standard_normal(n))
    spans = _excited({"excitation": excitation_summary(u, fs).to_dict()})
    assert spans is not None and len(spans) == 2
    f, p = signal.welch(u - u.mean(), fs=fs, nperseg=4096)
    inside = np.zeros_like(f, dtype=bool)
    for lo, hi in spans:
        inside |= (f / fs >= lo) & (f / fs <= hi)
    assert p[inside].sum() > 0.95 * p.sum()
    assert inside.mean() < 0.05  # narrow: not the whole stretch 0.5-11.5 Hz
    between = (f > 3.0) & (f < 8.0)
    assert not np.any(inside & between)
    plot = h1_gain_phase(np.linspace(0, 0.5, 64), np.ones(64), fs, excited=spans)
    shaded = [pt for pt in plot.figure.axes[0].patches]
    assert len(shaded) == len(spans)
    assert "where the estimation input has power" in plot.caption


def test_package_text_has_no_shorthand() -> None:
    """Docstrings, help, messages and notes in the package (what the API reference and the
    errors show) speak plainly too."""
    hits = [f"{p.relative_to(REPO)}:{i}: {line.strip()}"
            for p in sorted((REPO / "pmsm_sysid").rglob("*.py"))
            for i, line in enumerate(p.read_text(encoding="utf-8").splitlines(), 1)
            if SHORTHAND.search(line)]
    assert not hits, hits[:5]
