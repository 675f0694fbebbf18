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


STAGES = ("recording", "terms", "selection", "validation", "frequency", "physics", "plantfit",
          "online", "discrepancy", "fleet")


def _stage_graph() -> dict[str, set[str]]:
    """stage -> the other core stages its modules import (at any depth)."""
    graph: dict[str, set[str]] = {}
    for stage in STAGES:
        deps = {i.split(".")[2] for p in _modules(f"core/{stage}") for i in _imports(p)
                if i.startswith("pmsm_sysid.core.") and len(i.split(".")) > 2}
        graph[stage] = deps & set(STAGES) - {stage}
    return graph


def test_core_is_grouped_by_stage() -> None:
    """core/ holds the stage subpackages and the shared error types, nothing else."""
    core = PKG / "core"
    assert {p.name for p in core.glob("*.py")} == {"__init__.py", "errors.py"}
    assert {p.name for p in core.iterdir() if p.is_dir() and p.name != "__pycache__"} \
        == set(STAGES)


def test_every_stage_reexports_its_public_names() -> None:
    import importlib

    for stage in STAGES:
        mod = importlib.import_module(f"pmsm_sysid.core.{stage}")
        names = getattr(mod, "__all__", None)
        assert names, stage
        assert all(getattr(mod, n, None) is not None for n in names), stage
        assert mod.__doc__, stage


def test_no_import_cycle_between_stages() -> None:
    graph = _stage_graph()
    order: list[str] = []

    def visit(stage: str, path: tuple[str, ...]) -> None:
        assert stage not in path, " -> ".join((*path, stage))
        if stage not in order:
            for dep in sorted(graph[stage]):
                visit(dep, (*path, stage))
            order.append(stage)

    for stage in STAGES:
        visit(stage, ())
    # the data flow reads from the tree: a recording comes first, the discrepancy last; the
    # fleet's table and trends take their results as plain data (no stage imports them)
    assert graph["recording"] == set() and graph["terms"] == set()
    assert not any("discrepancy" in deps for deps in graph.values())
    assert not any("fleet" in deps for deps in graph.values())
    # fitting a plant from a recording comes before comparing a recording against a plant
    assert "plantfit" in graph["discrepancy"] and "discrepancy" not in graph["plantfit"]


def _module_graph() -> dict[str, set[str]]:
    """core module -> the core modules it imports, at any depth (function-level too)."""
    mods = {".".join(p.relative_to(PKG.parent).with_suffix("").parts): p
            for p in _modules("core") if p.name != "__init__.py"}
    return {name: {i for i in _imports(path) if i in mods and i != name}
            for name, path in mods.items()}


def _cycle(graph: dict[str, set[str]]) -> list[str]:
    """One import cycle of ``graph`` as a path, or [] (depth-first, colouring)."""
    state: dict[str, int] = {}
    stack: list[str] = []

    def visit(node: str) -> list[str]:
        state[node] = 1
        stack.append(node)
        for dep in sorted(graph[node]):
            if state.get(dep) == 1:
                return [*stack[stack.index(dep):], dep]
            if dep not in state and (found := visit(dep)):
                return found
        stack.pop()
        state[node] = 2
        return []

    for node in sorted(graph):
        if node not in state and (found := visit(node)):
            return found
    return []


def test_no_import_cycle_between_core_modules() -> None:
    """Not even a function-level import closes a circle (a module that needs another's
    names at run time and is needed by it is one module split in the wrong place)."""
    graph = _module_graph()
    assert len(graph) > 40
    assert _cycle(graph) == [], " -> ".join(_cycle(graph))


def test_the_cycle_finder_finds_a_cycle() -> None:
    assert _cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    assert _cycle({"a": {"b"}, "b": set()}) == []
