"""Rewrite pyproject.toml's per-module mypy relaxations: exactly what each module not yet clean under the
strict [tool.mypy] settings needs, nothing more (the typing gate, the layout work).

    python tests/benchmarks/mypy_overrides.py          # rewrites the blocks after the marker line
    python tests/benchmarks/mypy_overrides.py --check  # exit 1 if they would change

It runs mypy on a copy of the settings without the per-module blocks, reads each module's error codes,
turns them into the narrowest relaxation (``no-untyped-def``: ``disallow_untyped_defs`` and
``disallow_incomplete_defs`` off, bodies still checked; any other code: ``disable_error_code``), and repeats
until mypy passes (relaxing one check can reveal another). Modules with the same relaxation share a block.
A module annotated since loses its block the next time this runs; then ``mypy_coverage.py`` counts it.
"""

from __future__ import annotations

import re
import subprocess
import sys
import tempfile
from collections import defaultdict
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
PYPROJECT = ROOT / "pyproject.toml"
MARKER = "# -- per-module relaxations: written by tests/benchmarks/mypy_overrides.py (do not edit by hand) --"
ERROR = re.compile(r"^(arshadow/[^:]+\.py):\d+: error: .*\[([a-z-]+)\]$")
UNTYPED = "no-untyped-def"


def module_name(path: str) -> str:
    """``arshadow/geometry/mesh.py`` -> ``arshadow.geometry.mesh`` (a package's ``__init__`` -> the package)."""
    parts = Path(path).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def blocks(codes: dict[str, set[str]]) -> str:
    """The TOML override blocks for ``{module: error codes}``, modules with the same codes grouped."""
    groups: dict[tuple[str, ...], list[str]] = defaultdict(list)
    for mod, cs in codes.items():
        groups[tuple(sorted(cs))].append(mod)
    out = []
    for cs, mods in sorted(groups.items(), key=lambda kv: (-len(kv[1]), kv[0])):
        others = [c for c in cs if c != UNTYPED]
        why = []
        if UNTYPED in cs:
            why.append("functions not yet annotated (their bodies are still checked)")
        if others:
            why.append(f"errors not yet fixed in their code: {', '.join(others)}")
        lines = [f"# {'; '.join(why)}", "[[tool.mypy.overrides]]", "module = ["]
        lines += [f'  "{m}",' for m in sorted(mods)]
        lines.append("]")
        if UNTYPED in cs:
            lines += ["disallow_untyped_defs = false", "disallow_incomplete_defs = false"]
        if others:
            lines.append("disable_error_code = [" + ", ".join(f'"{c}"' for c in others) + "]")
        out.append("\n".join(lines))
    return "\n\n".join(out)


def run_mypy(config: str) -> list[tuple[str, str]]:
    with tempfile.NamedTemporaryFile("w", suffix=".toml", dir=ROOT, delete=False) as fh:
        fh.write(config)
    try:
        res = subprocess.run(
            [sys.executable, "-m", "mypy", "--config-file", fh.name],
            cwd=ROOT,
            capture_output=True,
            text=True,
        )
    finally:
        Path(fh.name).unlink()
    found = [(m.group(1), m.group(2)) for m in map(ERROR.match, res.stdout.splitlines()) if m]
    if res.returncode not in (0, 1) or (res.returncode == 1 and not found):
        sys.exit(f"mypy failed:\n{res.stdout}\n{res.stderr}")
    return found


def main() -> int:
    text = PYPROJECT.read_text(encoding="utf-8")
    head, sep, old = text.partition(MARKER)
    if not sep:
        sys.exit(f"{PYPROJECT}: no marker line {MARKER!r}")
    codes: dict[str, set[str]] = defaultdict(set)
    for _ in range(6):
        body = blocks(codes)
        found = run_mypy(head + MARKER + "\n\n" + body + "\n")
        if not found:
            break
        for path, code in found:
            codes[module_name(path)].add(code)
    else:
        sys.exit("mypy still reports errors after six rounds of relaxations")
    new = head + MARKER + "\n\n" + body + ("\n" if body else "")
    if "--check" in sys.argv:
        if new != text:
            print("pyproject.toml's mypy relaxations are out of date: run python tests/benchmarks/mypy_overrides.py")
            return 1
        return 0
    PYPROJECT.write_text(new, encoding="utf-8")
    print(f"{len(codes)} modules relaxed")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
