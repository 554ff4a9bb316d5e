"""The README's code runs as written and gives the success the README states."""

import re

from flownav.evaluation.metrics import summarize
from flownav.paths import REPO_ROOT


def readme_text() -> str:
    return (REPO_ROOT / "README.md").read_text()


def test_bring_your_own_flow_snippet_runs_and_succeeds_as_stated(monkeypatch):
    text = readme_text()
    blocks = re.findall(r"```python\n(.*?)```", text, flags=re.S)
    assert blocks, "the README lost its 'Bring your own flow' example"
    stated = re.search(r"success\s+[\d.]+%, Wilson 95% interval \[([\d.]+), ([\d.]+)\]", text)
    assert stated, "the README no longer states the example's success interval"
    lo, hi = (float(v) / 100 for v in stated.groups())
    monkeypatch.chdir(REPO_ROOT)
    namespace: dict = {}
    exec(compile(blocks[0], "README.md", "exec"), namespace)  # noqa: S102 - our own README
    episodes = namespace["episodes"]
    assert len(episodes) == 1000
    rate = summarize(episodes.status, episodes.time)["success_rate"]
    assert lo <= rate <= hi, f"the README example now succeeds in {rate:.1%}, outside its stated [{lo:.1%}, {hi:.1%}]"
