"""The import rules of docs/architecture.md, checked on the source text."""
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
FORBIDDEN = {
    "design": ["labapp", "drivers", "analysis", "PySide6", "pyqtgraph"],
    "analysis": ["labapp", "drivers", "design", "PySide6", "pyqtgraph"],
    "drivers": ["labapp", "design", "analysis", "PySide6", "pyqtgraph"],
}


@pytest.mark.parametrize("package", sorted(FORBIDDEN))
def test_package_imports_only_what_it_may(package):
    pattern = re.compile(r"^\s*(?:from|import)\s+(\w+)", re.MULTILINE)
    offenders = []
    for path in (ROOT / package).rglob("*.py"):
        for name in pattern.findall(path.read_text()):
            if name in FORBIDDEN[package]:
                offenders.append(f"{path.relative_to(ROOT)} imports {name}")
    assert not offenders, offenders


def test_qt_only_in_gui():
    pattern = re.compile(r"^\s*(?:from|import)\s+(PySide6|pyqtgraph)", re.MULTILINE)
    offenders = [str(p.relative_to(ROOT)) for p in (ROOT / "labapp").rglob("*.py")
                 if "gui" not in p.relative_to(ROOT).parts and pattern.search(p.read_text())]
    assert not offenders, offenders
