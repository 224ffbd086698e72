"""The stub speaks MAVLink with its own code: it never imports the companion's wire.

If both sides shared ``ezcompanion.wire``, a wrong unit or frame there would be made twice
and cancel out in every loopback test.
"""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import pytest

STUB = Path(__file__).resolve().parents[1] / "sitl_stub"


def _imported_modules(path: Path) -> set[str]:
    names: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module is not None:
            names.add(node.module)
            names.update(f"{node.module}.{alias.name}" for alias in node.names)
    return names


@pytest.mark.parametrize("path", sorted(STUB.glob("*.py")), ids=lambda p: p.name)
def test_no_stub_module_imports_the_companion_wire(path: Path) -> None:
    bad = {n for n in _imported_modules(path)
           if n == "ezcompanion.wire" or n.startswith("ezcompanion.wire.")}
    assert not bad, f"{path.name} imports {sorted(bad)}"


def test_importing_the_stub_does_not_load_the_companion_wire() -> None:
    code = ("import sys, sitl_stub, sitl_stub.cli; "
            "print(sorted(m for m in sys.modules if m.startswith('ezcompanion.wire')))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True, timeout=60).stdout.strip()
    assert out == "[]", out
