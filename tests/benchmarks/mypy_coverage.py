"""The typing gate's figure (the layout work): the share of the package's lines (``arshadow/**/*.py``) in
modules that mypy checks with the full strict settings of pyproject.toml's [tool.mypy], i.e. modules no
``[[tool.mypy.overrides]]`` block relaxes. .ci/run prints it right after ``mypy``.

    python tests/benchmarks/mypy_coverage.py          # one line: the share, lines and modules
    python tests/benchmarks/mypy_coverage.py --list   # and the relaxed modules, largest first
"""

from __future__ import annotations

import fnmatch
import sys
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def module_name(path: Path) -> str:
    """``arshadow/geometry/mesh.py`` -> ``arshadow.geometry.mesh`` (a package's ``__init__`` -> the package)."""
    parts = path.relative_to(ROOT).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def relaxed_patterns(pyproject: Path) -> list[str]:
    """The module patterns of every override block (``a.b``, ``a.b.*``): each relaxes something."""
    mypy = tomllib.loads(pyproject.read_text(encoding="utf-8"))["tool"]["mypy"]
    pats: list[str] = []
    for block in mypy.get("overrides", []):
        mods = block["module"]
        pats += [mods] if isinstance(mods, str) else list(mods)
    return pats


def is_relaxed(module: str, patterns: list[str]) -> bool:
    """mypy's matching: ``a.b.*`` covers ``a.b`` and everything below it."""
    for p in patterns:
        if p == module or (p.endswith(".*") and (module == p[:-2] or fnmatch.fnmatch(module, p))):
            return True
    return False


def main() -> int:
    patterns = relaxed_patterns(ROOT / "pyproject.toml")
    total = strict = n_strict = 0
    files = sorted((ROOT / "arshadow").rglob("*.py"))
    relaxed: list[tuple[int, str]] = []
    for f in files:
        n = len(f.read_text(encoding="utf-8").splitlines())
        total += n
        mod = module_name(f)
        if is_relaxed(mod, patterns):
            relaxed.append((n, mod))
        else:
            strict += n
            n_strict += 1
    print(
        f"mypy full strict: {100.0 * strict / max(total, 1):.1f} % of lines "
        f"({strict} of {total} lines; {n_strict} of {len(files)} modules)"
    )
    if "--list" in sys.argv:
        for n, mod in sorted(relaxed, reverse=True):
            print(f"  relaxed: {mod} ({n} lines)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
