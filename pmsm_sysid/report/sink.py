"""Where figures go: saved as PNG beside index.html, their drawn data kept, progress shown."""

from __future__ import annotations

from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

from ..plots.base import Plot, save
from ..progress import Bar
from .html import Image, Note, image


class Sink:
    """Collects the figures of one report in ``out_dir`` and ticks a progress bar."""

    def __init__(self, out_dir: Path, total: int, label: str = "report") -> None:
        self.out_dir = out_dir
        self.bar = Bar(total, label)
        self.files: list[Path] = []
        self.data: dict[str, Mapping[str, Any]] = {}
        self.notes: list[str] = []

    def tick(self, n: int = 1) -> None:
        self.bar.update(n)

    def figure(self, plot: Plot) -> Image:
        """Save one figure, keep what it drew, return its page block."""
        path = save(plot, self.out_dir)
        plot.figure.clear()
        self.files.append(path)
        self.data[plot.name] = plot.data
        self.tick()
        return image(path, plot.caption)

    def attempt(self, what: str, make: Callable[[], Plot]) -> Image | Note:
        """A figure that may be impossible for this input (e.g. an unstable model's
        free run): the page then says why instead of failing the whole report."""
        from ..core.errors import PmsmSysidError

        try:
            return self.figure(make())
        except PmsmSysidError as exc:
            self.tick()
            text = f"{what}: not drawn ({exc})"
            self.notes.append(text)
            return Note(text)

    def close(self) -> None:
        self.bar.close()
