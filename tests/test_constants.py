"""One source for each physical constant: the print density is defined once (design.fabrication.printability)."""
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_the_print_density_is_defined_once():
    pattern = re.compile(r"^\s*[A-Za-z0-9_]*\s*(:\s*float)?\s*=\s*[^#\n]*\b1\.32\b", re.M)
    hits = [f"{p.relative_to(ROOT)}" for pkg in ("design", "analysis", "drivers", "labapp")
            for p in (ROOT / pkg).rglob("*.py") if pattern.search(p.read_text())]
    assert hits == ["design/material.py"]
