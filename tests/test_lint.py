"""The code base stays `ruff check` clean and `ruff format` formatted (part of the one test command CI runs),
defines its error types in one module, and writes every JSON file atomically."""

import ast
import re
import shutil
import subprocess

import pytest

from flownav.paths import REPO_ROOT

SOURCES = [
    *(REPO_ROOT / "flownav").rglob("*.py"),
    *(REPO_ROOT / "scripts").glob("*.py"),
    *(REPO_ROOT / "benchmarks").glob("*.py"),
    REPO_ROOT / "train.py",
    REPO_ROOT / "evaluate.py",
]


@pytest.mark.parametrize("command", [["check", "."], ["format", "--check", "."]], ids=["check", "format"])
def test_ruff_is_clean(command):
    ruff = shutil.which("ruff")
    if ruff is None:
        pytest.fail("ruff is not installed: pip install -e '.[dev]'")
    result = subprocess.run([ruff, *command], cwd=REPO_ROOT, capture_output=True, text=True)
    assert result.returncode == 0, result.stdout + result.stderr


def test_error_types_live_in_errors_py():
    """A user error is one of flownav.errors' types: no module defines its own subclass of them."""
    import flownav.errors as errors

    names = {n for n, v in vars(errors).items() if isinstance(v, type) and issubclass(v, Exception)}
    found = []
    for path in SOURCES:
        if path == REPO_ROOT / "flownav" / "errors.py":
            continue
        for node in ast.walk(ast.parse(path.read_text())):
            bases = [getattr(b, "id", getattr(b, "attr", "")) for b in getattr(node, "bases", [])]
            if isinstance(node, ast.ClassDef) and names & set(bases):
                found.append(f"{path.relative_to(REPO_ROOT)}: class {node.name}({', '.join(bases)})")
    assert not found, f"error types outside flownav/errors.py: {found}"


def test_json_files_are_written_atomically():
    """JSON goes to disk through flownav.atomic (a killed process leaves the old file or the new one)."""
    plain = re.compile(r"json\.dump\(|\.write_text\(.*json|json.*\.write_text\(")
    found = [
        f"{path.relative_to(REPO_ROOT)}:{i}: {line.strip()}"
        for path in SOURCES
        for i, line in enumerate(path.read_text().splitlines(), 1)
        if plain.search(line)
    ]
    assert not found, f"JSON written without flownav.atomic: {found}"
