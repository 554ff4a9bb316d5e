"""The README's code runs as written."""

import re

from flownav.paths import REPO_ROOT


def readme_python_blocks() -> list[str]:
    text = (REPO_ROOT / "README.md").read_text()
    return re.findall(r"```python\n(.*?)```", text, flags=re.S)


def test_bring_your_own_flow_snippet_runs(monkeypatch):
    blocks = readme_python_blocks()
    assert blocks, "the README lost its 'Bring your own flow' example"
    monkeypatch.chdir(REPO_ROOT)
    namespace: dict = {}
    exec(compile(blocks[0], "README.md", "exec"), namespace)  # noqa: S102 - our own README
    assert len(namespace["episodes"]) == 1000
