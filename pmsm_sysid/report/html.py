"""One self-contained HTML page, built from a Jinja2 template (``templates/page.html.j2``):
inline CSS, no scripts, no network; every figure is embedded in the page as a base64 PNG (the
same PNG is also kept beside ``index.html``), so the page opens offline and can be mailed on
its own. Tables are HTML tables."""

from __future__ import annotations

import base64
import struct
from collections.abc import Sequence
from dataclasses import dataclass
from datetime import UTC, datetime
from functools import cache
from pathlib import Path
from typing import ClassVar

import jinja2

from ..core.errors import DataError


@dataclass(frozen=True)
class Table:
    caption: str
    header: tuple[str, ...]
    rows: tuple[tuple[str, ...], ...]
    kind: ClassVar[str] = "table"


@dataclass(frozen=True)
class Image:
    """A PNG embedded in the page; ``file`` is the name of its copy beside index.html."""

    file: str
    caption: str
    width: int
    height: int
    base64: str = ""
    kind: ClassVar[str] = "image"


@dataclass(frozen=True)
class Note:
    text: str
    kind: ClassVar[str] = "note"


@dataclass(frozen=True)
class Facts:
    """A definition list of (label, value) pairs."""

    items: tuple[tuple[str, str], ...]
    kind: ClassVar[str] = "facts"


Block = Table | Image | Note | Facts


@dataclass(frozen=True)
class Section:
    title: str
    blocks: tuple[Block, ...]


def png_size(path: str | Path) -> tuple[int, int]:
    """(width, height) from a PNG's IHDR chunk; DataError if it is not a PNG."""
    with open(path, "rb") as fh:
        head = fh.read(24)
    if len(head) < 24 or head[:8] != b"\x89PNG\r\n\x1a\n" or head[12:16] != b"IHDR":
        raise DataError(f"{path}: not a PNG file")
    w, h = struct.unpack(">II", head[16:24])
    return int(w), int(h)


def image(path: Path, caption: str) -> Image:
    """The PNG at ``path`` as a page block (its bytes embedded)."""
    w, h = png_size(path)
    data = base64.b64encode(path.read_bytes()).decode("ascii")
    return Image(file=path.name, caption=caption, width=w, height=h, base64=data)


@cache
def _template() -> jinja2.Template:
    env = jinja2.Environment(loader=jinja2.PackageLoader("pmsm_sysid.report", "templates"),
                             autoescape=True, undefined=jinja2.StrictUndefined,
                             trim_blocks=True, lstrip_blocks=True)
    return env.get_template("page.html.j2")


def render_page(title: str, sections: Sequence[Section], subtitle: str = "") -> str:
    """The whole page as a string (UTF-8, no external resources)."""
    stamp = datetime.now(UTC).strftime("%Y-%m-%d %H:%M UTC")
    return _template().render(title=title, subtitle=subtitle, sections=list(sections),
                              stamp=stamp) + "\n"


def write_page(out_dir: str | Path, title: str, sections: Sequence[Section],
               subtitle: str = "") -> Path:
    """Write ``out_dir/index.html``; every figure must already be saved there."""
    out = Path(out_dir)
    for s in sections:
        for b in s.blocks:
            if isinstance(b, Image) and not (out / b.file).is_file():
                raise DataError(f"report: figure {b.file} missing in {out}")
    path = out / "index.html"
    path.write_text(render_page(title, sections, subtitle), encoding="utf-8")
    return path
