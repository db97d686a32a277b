"""Modules that fit in one head (docs/architecture.md, "Checks that keep the house"): no module of the four
packages, the benchmarks or the studies over 700 lines, no function over 100."""
import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
FOLDERS = ("design", "analysis", "drivers", "labapp", "benchmarks", "studies")
MAX_MODULE_LINES = 700
MAX_FUNCTION_LINES = 100


def _sources() -> list[Path]:
    return sorted(path for folder in FOLDERS for path in (ROOT / folder).rglob("*.py"))


def test_every_module_and_function_fits_in_one_head():
    sources = _sources()
    assert len(sources) > 100                      # the folders were found
    too_long = []
    for path in sources:
        text = path.read_text(encoding="utf-8")
        name = path.relative_to(ROOT)
        lines = len(text.splitlines())
        if lines > MAX_MODULE_LINES:
            too_long.append(f"{name}: {lines} lines (at most {MAX_MODULE_LINES})")
        too_long += [f"{name}: {node.name} {node.end_lineno - node.lineno + 1} lines (at most {MAX_FUNCTION_LINES})"
                     for node in ast.walk(ast.parse(text))
                     if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef))
                     and node.end_lineno - node.lineno + 1 > MAX_FUNCTION_LINES]
    assert not too_long, "split by job: " + "; ".join(too_long)
