"""One self-contained HTML page: inline CSS, no scripts, no network; figures are PNG files
beside ``index.html`` referenced by relative name; tables are HTML tables."""

from __future__ import annotations

import html
import struct
from collections.abc import Sequence
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path

from ..core.errors import DataError

CSS = """
body{font-family:system-ui,-apple-system,"Segoe UI",sans-serif;max-width:1000px;margin:2em auto;
padding:0 1em;color:#222;line-height:1.45}
h1{font-size:1.6em;border-bottom:2px solid #444;padding-bottom:.2em}
h2{font-size:1.25em;margin-top:2em;border-bottom:1px solid #bbb}
figure{margin:1.2em 0;text-align:center}
figure img{max-width:100%;height:auto;border:1px solid #ddd}
figcaption{font-size:.9em;color:#444;text-align:left;margin-top:.3em}
table{border-collapse:collapse;margin:1em 0;font-size:.9em}
caption{text-align:left;font-weight:600;padding-bottom:.3em}
th,td{border:1px solid #ccc;padding:.25em .6em;text-align:right}
th{background:#f3f3f3}td:first-child,th:first-child{text-align:left;font-family:monospace}
p.note{background:#fff7e0;border-left:4px solid #e0a800;padding:.4em .8em;font-size:.9em}
dl{display:grid;grid-template-columns:max-content auto;gap:.2em 1em;font-size:.9em}
dt{font-weight:600}dd{margin:0}
"""


@dataclass(frozen=True)
class Table:
    caption: str
    header: tuple[str, ...]
    rows: tuple[tuple[str, ...], ...]


@dataclass(frozen=True)
class Image:
    """A PNG beside index.html (``file`` is its relative name)."""

    file: str
    caption: str
    width: int
    height: int


@dataclass(frozen=True)
class Note:
    text: str


@dataclass(frozen=True)
class Facts:
    """A definition list of (label, value) pairs."""

    items: tuple[tuple[str, str], ...]


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
    w, h = png_size(path)
    return Image(file=path.name, caption=caption, width=w, height=h)


def _esc(text: str) -> str:
    return html.escape(text, quote=True)


def _table(t: Table) -> str:
    head = "".join(f"<th>{_esc(h)}</th>" for h in t.header)
    body = "".join("<tr>" + "".join(f"<td>{_esc(c)}</td>" for c in row) + "</tr>"
                   for row in t.rows)
    return (f"<table><caption>{_esc(t.caption)}</caption><thead><tr>{head}</tr></thead>"
            f"<tbody>{body}</tbody></table>")


def _block(b: Block) -> str:
    if isinstance(b, Table):
        return _table(b)
    if isinstance(b, Image):
        return (f'<figure><img src="{_esc(b.file)}" width="{b.width}" height="{b.height}" '
                f'alt="{_esc(b.caption)}"><figcaption>{_esc(b.caption)}</figcaption></figure>')
    if isinstance(b, Note):
        return f'<p class="note">{_esc(b.text)}</p>'
    items = "".join(f"<dt>{_esc(k)}</dt><dd>{_esc(v)}</dd>" for k, v in b.items)
    return f"<dl>{items}</dl>"


def render_page(title: str, sections: Sequence[Section], subtitle: str = "") -> str:
    """The whole page as a string (UTF-8, no external resources)."""
    stamp = datetime.now(UTC).strftime("%Y-%m-%d %H:%M UTC")
    parts = ["<!DOCTYPE html>", '<html lang="en"><head><meta charset="utf-8">',
             '<meta name="viewport" content="width=device-width, initial-scale=1">',
             f"<title>{_esc(title)}</title><style>{CSS}</style></head><body>",
             f"<h1>{_esc(title)}</h1>"]
    if subtitle:
        parts.append(f"<p>{_esc(subtitle)}</p>")
    toc = "".join(f'<li><a href="#s{i}">{_esc(s.title)}</a></li>'
                  for i, s in enumerate(sections))
    parts.append(f"<ul>{toc}</ul>")
    for i, s in enumerate(sections):
        parts.append(f'<section id="s{i}"><h2>{_esc(s.title)}</h2>')
        parts.extend(_block(b) for b in s.blocks)
        parts.append("</section>")
    parts.append(f'<footer><p style="color:#888;font-size:.8em">pmsm-sysid report, '
                 f"{stamp}</p></footer></body></html>")
    return "\n".join(parts) + "\n"


def write_page(out_dir: str | Path, title: str, sections: Sequence[Section],
               subtitle: str = "") -> Path:
    """Write ``out_dir/index.html``; every referenced image must already exist there."""
    out = Path(out_dir)
    for s in sections:
        for b in s.blocks:
            if isinstance(b, Image) and not (out / b.file).is_file():
                raise DataError(f"report: figure {b.file} missing in {out}")
    path = out / "index.html"
    path.write_text(render_page(title, sections, subtitle), encoding="utf-8")
    return path
