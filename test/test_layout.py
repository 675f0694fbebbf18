"""Package layout: dependencies point one way (report draws with plots; plots never import
report; the numerical core imports neither ROS nor plotting nor bag I/O)."""

from __future__ import annotations

import ast
from pathlib import Path

PKG = Path(__file__).resolve().parents[1] / "pmsm_sysid"


def _imports(path: Path) -> set[str]:
    """Absolute names of every module ``path`` imports, at any depth (function-level too)."""
    package = ".".join(path.relative_to(PKG.parent).with_suffix("").parts[:-1])
    out: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            out |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom):
            base = package.split(".")
            if node.level:
                base = base[: len(base) - node.level + 1]
                name = ".".join([*base, node.module] if node.module else base)
            else:
                name = node.module or ""
            out.add(name)
            out |= {f"{name}.{a.name}" for a in node.names}
    return out


def _modules(sub: str) -> list[Path]:
    found = sorted((PKG / sub).rglob("*.py"))
    assert found, sub
    return found


def test_plots_never_import_report() -> None:
    bad = {str(p.relative_to(PKG)): sorted(i for i in _imports(p)
                                           if i.startswith("pmsm_sysid.report"))
           for p in _modules("plots")}
    assert not {k: v for k, v in bad.items() if v}


def test_report_uses_plots() -> None:
    assert any(i.startswith("pmsm_sysid.plots") for p in _modules("report") for i in _imports(p))


def test_core_imports_no_ros_no_plotting_no_bag_io() -> None:
    banned = ("rclpy", "rosbags", "matplotlib", "pmsm_sysid.bagio", "pmsm_sysid.nodes",
              "pmsm_sysid.plots", "pmsm_sysid.report", "pmsm_sysid.cli")
    bad = {str(p.relative_to(PKG)): sorted(i for i in _imports(p) if i.startswith(banned))
           for p in _modules("core")}
    assert not {k: v for k, v in bad.items() if v}
