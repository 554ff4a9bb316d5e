"""The README's code runs as written and gives the success the README states."""

import re

import pytest

from flownav.paths import REPO_ROOT


def readme_text() -> str:
    return (REPO_ROOT / "README.md").read_text()


def run_block(containing: str, cwd, monkeypatch) -> dict:
    """Run the README's one Python block that contains ``containing``, in ``cwd``; its namespace."""
    blocks = [b for b in re.findall(r"```python\n(.*?)```", readme_text(), flags=re.S) if containing in b]
    assert len(blocks) == 1, f"the README should hold one Python example with {containing!r}"
    monkeypatch.chdir(cwd)
    namespace: dict = {}
    exec(compile(blocks[0], "README.md", "exec"), namespace)  # noqa: S102 - our own README
    return namespace


def test_bring_your_own_flow_snippet_runs_and_succeeds_as_stated(monkeypatch):
    text = readme_text()
    blocks = re.findall(r"```python\n(.*?)```", text, flags=re.S)
    assert blocks, "the README lost its 'Bring your own flow' example"
    stated = re.search(r"reaches its target in (\d+) of the 1,000 episodes", text)
    assert stated, "the README does not state the example's successes"
    monkeypatch.chdir(REPO_ROOT)
    namespace: dict = {}
    exec(compile(blocks[0], "README.md", "exec"), namespace)  # noqa: S102 - our own README
    summary = namespace["result"].summary
    assert summary["episodes"] == 1000
    assert summary["successes"] == int(stated.group(1)), "the README states another count: rerun and restate it"


def test_netcdf_snippet_runs_and_the_student_reaches_the_target(monkeypatch, tmp_path):
    (tmp_path / "checkpoints").symlink_to(REPO_ROOT / "checkpoints")  # it writes current.nc where it runs
    summary = run_block("load_xarray_flow", tmp_path, monkeypatch)["result"].summary
    stated = re.search(r"# (\d+) of 200 reached the target", readme_text())
    assert stated, "the README does not state the example's successes"
    assert summary["episodes"] == 200
    assert summary["successes"] == int(stated.group(1)), "the README states another count: rerun and restate it"


@pytest.mark.slow
def test_gymnasium_snippet_runs(monkeypatch):
    namespace = run_block("flownav/CylinderWake-v0", REPO_ROOT, monkeypatch)
    assert namespace["model"].num_timesteps == 2048
    assert namespace["vec"].observation_space.shape == (256, 9)


def test_the_module_map_lists_every_module():
    """The README's "Where things live" names every module of flownav/ and every script."""
    text = readme_text()
    start = text.index("## Where things live")
    block = text[start : text.index("```", text.index("```", start) + 3)]
    files = [p for p in (REPO_ROOT / "flownav").rglob("*.py") if p.name not in ("__init__.py", "__main__.py")]
    files += list((REPO_ROOT / "scripts").glob("*.py"))
    missing = sorted(str(p.relative_to(REPO_ROOT)) for p in files if p.name not in block)
    assert not missing, f"the README's module map does not name {missing}"


def test_the_tests_the_docs_name_exist():
    """Every ``tests/<file>.py`` and ``tests/<file>.py::<test>`` named in the README and docs/ is there."""
    texts = [readme_text(), *(p.read_text() for p in sorted((REPO_ROOT / "docs").glob("*.md")))]
    named = {m.groups() for text in texts for m in re.finditer(r"tests/(test_\w+\.py)(?:::(\w+))?", text)}
    assert named, "the docs name no tests"
    missing = []
    for file, test in sorted(named, key=lambda n: (n[0], n[1] or "")):
        path = REPO_ROOT / "tests" / file
        if not path.is_file() or (test and not re.search(rf"^def {test}\(", path.read_text(), flags=re.M)):
            missing.append(f"tests/{file}" + (f"::{test}" if test else ""))
    assert not missing, f"the docs name tests that do not exist: {missing}"


def test_the_policy_table_is_what_scripts_policy_table_prints(capsys):
    """The README's first table is the output of python scripts/policy_table.py on the shipped results."""
    from load import load_module

    script = load_module("scripts/policy_table.py")
    script.main()
    table = capsys.readouterr().out.strip().splitlines()
    assert len(table) == 2 + len(script.POLICIES)  # header, rule, one row per policy
    lines = readme_text().splitlines()
    start = lines.index(table[0])
    assert lines[start : start + len(table)] == table
