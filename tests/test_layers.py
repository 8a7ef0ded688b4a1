"""The layer rule of docs/architecture.md, read from the imports: a package never imports a
package of a higher tier (same tier is allowed between packages that do not import each
other both ways). Imports inside functions count too."""

from __future__ import annotations

import ast
from pathlib import Path

SRC = Path(__file__).resolve().parents[1] / "src" / "eddiebot"

#: lowest first; packages in one tuple share a tier
TIERS: tuple[tuple[str, ...], ...] = (
    ("geometry",),
    ("msgs",),
    ("core",),
    ("transport", "maps", "perception", "bag"),
    ("robot",),
    ("base", "sim"),
    ("slam", "nav", "vslam"),
    ("registry",),
    ("viz",),
    ("demo",),
    ("explore",),
    ("cli",),
)
TIER = {pkg: i for i, tier in enumerate(TIERS) for pkg in tier}

def _imports(path: Path) -> set[str]:
    names: list[str] = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names.append(node.module)
        elif isinstance(node, ast.Import):
            names.extend(a.name for a in node.names)
        elif (isinstance(node, ast.Call) and getattr(node.func, "attr", "") == "import_module"
              and node.args and isinstance(node.args[0], ast.Constant)):
            names.append(str(node.args[0].value))
    return {n.split(".")[1] for n in names if n.startswith("eddiebot.") and "." in n}


def test_every_package_has_a_tier():
    packages = {p.name for p in SRC.iterdir() if p.is_dir() and (p / "__init__.py").exists()}
    packages |= {p.stem for p in SRC.glob("*.py") if p.stem != "__init__"}
    assert packages <= set(TIER), f"packages without a tier: {sorted(packages - set(TIER))}"


def _package_imports() -> list[tuple[str, str, str]]:
    """(file relative to the package root, its package, an eddiebot package it imports)."""
    out = []
    for path in SRC.rglob("*.py"):
        rel = path.relative_to(SRC)
        pkg = rel.parts[0] if len(rel.parts) > 1 else rel.stem
        if pkg in TIER:
            out.extend((rel.as_posix(), pkg, target) for target in _imports(path)
                       if target != pkg and target in TIER)
    return out


def test_lower_never_imports_higher():
    violations = [f"{rel} ({pkg}) imports eddiebot.{target}"
                  for rel, pkg, target in _package_imports() if TIER[target] > TIER[pkg]]
    assert not violations, "\n".join(sorted(violations))


def test_packages_of_one_tier_never_import_each_other_both_ways():
    edges = {(pkg, target) for _, pkg, target in _package_imports()
             if TIER[target] == TIER[pkg]}
    both = sorted(f"{a} <-> {b}" for a, b in edges if (b, a) in edges and a < b)
    assert not both, "\n".join(both)
