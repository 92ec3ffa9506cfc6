"""The layout section of docs/development.md names every module of the package, and
nothing that is gone."""

from __future__ import annotations

import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "src/scanplan"


def _layout_section() -> str:
    text = (ROOT / "docs/development.md").read_text(encoding="utf-8")
    start = text.index("Layout (`src/scanplan/`")
    return text[start : text.index("`tests/` mirrors the package", start)]


def _listed() -> dict[str, set[str]]:
    """Per top-level package, the module paths its layout entry names (`learn/` followed by
    its files names them under learn/)."""
    entries = re.split(r"^- ", _layout_section(), flags=re.M)[1:]
    listed: dict[str, set[str]] = {}
    for entry in entries:
        packages = re.findall(r"^`(\w+)/`(?: and `(\w+)/`)?", entry)[0]
        for package in filter(None, packages):
            listed.setdefault(package, set())
        current, sub = packages[0], ""
        for name in re.findall(r"`([\w/]+(?:\.py)?)`", entry):
            if name.endswith("/") and name.rstrip("/") in listed:
                current, sub = name.rstrip("/"), ""
            elif name.endswith("/"):
                sub = name
            elif name.endswith(".py"):
                listed[current].add(sub + name)
    return listed


def test_the_readme_layout_names_every_module_and_only_those():
    listed = _listed()
    actual = {
        p.name: {
            str(f.relative_to(p))
            for f in p.rglob("*.py")
            if f.name != "__init__.py" and "__pycache__" not in f.parts
        }
        for p in PACKAGE.iterdir()
        if p.is_dir() and (p / "__init__.py").exists()
    }
    assert set(listed) == set(actual)
    for package, modules in actual.items():
        named = {m.split("/")[-1] for m in listed[package]}
        missing = sorted(m for m in modules if m.split("/")[-1] not in named)
        gone = sorted(n for n in named if n not in {m.split("/")[-1] for m in modules})
        assert not missing, f"{package}/: not in the layout in docs/development.md: {missing}"
        assert not gone, f"{package}/: in the layout in docs/development.md but gone: {gone}"


def test_every_benchmark_script_imports_what_the_package_has(monkeypatch):
    """A module moved inside the package must not leave a benchmark that no longer starts
    (each script only defines things at import; its work is behind its main guard)."""
    import importlib.util

    monkeypatch.syspath_prepend(str(ROOT / "benchmarks"))  # scripts import their siblings
    for script in sorted((ROOT / "benchmarks").glob("*.py")):
        spec = importlib.util.spec_from_file_location(f"bench_{script.stem}", script)
        assert spec and spec.loader
        module = importlib.util.module_from_spec(spec)
        # Registered as importlib's recipe does: a script's dataclasses look their module up.
        monkeypatch.setitem(sys.modules, spec.name, module)
        spec.loader.exec_module(module)  # raises on an import that no longer resolves
