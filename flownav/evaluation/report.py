"""``results/paper.json`` (machine-readable, keyed by experiment) and ``REPORT.md`` (the paper's numbers
side by side with ours, Wilson intervals, the command and git commit that produced each table)."""

from __future__ import annotations

import json
import os
import time
from pathlib import Path

from flownav.atomic import atomic_write_text
from flownav.evaluation.kinds import KINDS
from flownav.paths import REPO_ROOT, RESULTS_DIR
from flownav.provenance import git_commit


def merge_results(path: Path, new: dict, prov: dict, log=print) -> dict:
    """Update ``path`` (results/paper.json) with the experiments just run; keep the others. An experiment this
    run skipped (an input it needs is missing here) keeps its measured result: a skip never replaces a measurement."""
    path = Path(path)
    old = {}
    if path.is_file():
        try:
            old = json.loads(path.read_text())
        except json.JSONDecodeError:
            old = {}
    experiments = dict(old.get("experiments", {}))
    for name, res in new.items():
        if res.get("skipped") and name in experiments and not experiments[name].get("skipped"):
            log(f"kept the measured result of {name} in {path} (this run skipped it: {'; '.join(res['missing'])})")
            continue
        experiments[name] = res | {"provenance": prov}
    data = {"format": "flownav-paper-results-v1", "experiments": experiments}
    atomic_write_text(path, json.dumps(data, indent=1, default=_json_default))
    return data


def _json_default(o):
    if hasattr(o, "tolist"):
        return o.tolist()
    return str(o)


# ----------------------------------------------------------------------------- markdown
def _rel(p, report_dir: Path) -> str:
    try:
        return os.path.relpath(Path(p).resolve(), report_dir.resolve())
    except ValueError:
        return str(p)


def _header(name: str, r: dict, command: str) -> list[str]:
    prov = r.get("provenance", {})
    lines = [f"## {r['title']}", ""]
    if r.get("paper_ref"):
        lines.append(f"Paper: {r['paper_ref']}.  ")
    ran = "" if prov.get("command") == command else f"ran as `{prov.get('command', '?')}`, "
    lines.append(
        f"Reproduce: `{r.get('command', '')}` ({ran}commit `{prov.get('commit', '?')}`, "
        f"{prov.get('date_utc', '?')} UTC, {r.get('seconds', '?')} s).  "
    )
    ck = r.get("policies") or {}
    if ck:
        lines.append(
            "Checkpoints: "
            + ", ".join(f"{k} = `{v['checkpoint']}` (sha256 {v['sha256']}, {v['obs']})" for k, v in ck.items())
        )
    lines.append("")
    for m in r.get("missing", []):
        lines.append(f"- **skipped** - {m}")
    if r.get("missing"):
        lines.append("")
    return lines


def _figures(r: dict, report_dir: Path) -> list[str]:
    out = []
    for f in r.get("figures", []) or []:
        image = "!" if Path(f).suffix in (".png", ".gif", ".jpg", ".svg") else ""  # a movie is a plain link
        out.append(f"{image}[{Path(f).stem}]({_rel(f, report_dir)})")
    return out + [""] if out else []


def _verdicts(exps: dict) -> list[str]:
    """The Targets section: each experiment's targets (its config's ``targets``), judged by its kind."""
    lines = []
    for r in exps.values():
        if r.get("kind") in KINDS:
            lines += KINDS[r["kind"]].verdicts(r)
    head = ["## Targets", "", "Targets and diagnostics of the suite's configs (reported, not asserted):", ""]
    nothing = "- Nothing to judge yet: no result of an entry with `targets:` (or its checkpoints are missing)."
    return head + (lines or [nothing]) + [""]


def paper_suite_keys() -> set[str]:
    """The experiments that ``+experiment=paper`` runs: the suite keys of the configs its defaults list."""
    from omegaconf import OmegaConf

    conf = REPO_ROOT / "conf" / "evaluate" / "experiment"
    names = OmegaConf.load(conf / "paper.yaml").defaults
    return {key for name in names for key in OmegaConf.load(conf / f"{name}.yaml").get("suite", {})}


def _performance(seconds: float | None, exps: dict) -> list[str]:
    lines = ["## Performance", ""]
    if seconds is not None:
        lines.append(f"- This run of `evaluate.py`: {seconds / 60:.1f} minutes.")
    paper = paper_suite_keys()
    minutes = {k: float(r.get("seconds") or 0) / 60 for k, r in exps.items()}
    in_paper = sum(m for k, m in minutes.items() if k in paper)
    lines.append(
        f"- The experiments of `+experiment=paper` below, as last run, took {in_paper:.1f} minutes together "
        "(goal: <= 60; the per-experiment times are in each section)."
    )
    others = sorted(k for k in minutes if k not in paper)
    if others:
        names = ", ".join(f"`{k}`" for k in others)
        lines.append(
            f"- The other experiments below ({names}), as last run: {sum(minutes[k] for k in others):.1f} minutes."
        )
    bench = REPO_ROOT / "benchmarks" / "results" / "eval_throughput.json"
    if bench.is_file():
        try:
            lines.append(f"- `python benchmarks/eval_throughput.py`: {json.loads(bench.read_text())['headline']}.")
        except (json.JSONDecodeError, KeyError):
            lines.append(
                "- benchmarks/results/eval_throughput.json has no readable headline: rerun "
                "`python benchmarks/eval_throughput.py`."
            )
    return lines + [""]


SHIPPED_RESULTS = RESULTS_DIR / "paper.json"  # what a shipped REPORT.md is written from


def write_report(
    data: dict,
    path: Path,
    command: str,
    seconds: float | None = None,
    commit: str | None = None,
    results: Path | None = None,
) -> Path:
    """REPORT.md from the merged results (every experiment run so far); ``commit``: the code that ran (default HEAD);
    ``results``: the file they are in (default: results/paper.json), named relative to the report."""
    path = Path(path)
    report_dir = path.parent
    results_name = os.path.relpath(results or SHIPPED_RESULTS, report_dir)
    exps = data.get("experiments", {})
    lines = [
        "# flownav: the paper's experiments, reproduced",
        "",
        "Written by `python evaluate.py +experiment=paper` (flownav/evaluation/report.py); this run: "
        f"`{command}` at commit `{commit or git_commit()}`, {time.strftime('%Y-%m-%d %H:%M', time.gmtime())} UTC. "
        f"Machine-readable results: `{results_name}`. How to run each experiment: `docs/evaluation.md`.",
        "",
        "Success rates carry Wilson 95% intervals; every episode is deterministic (policy mean action), one "
        "episode per env slot, no auto-reset. A table marked *skipped* names the command that produces what it "
        "lacks.",
        "",
    ]
    lines += _verdicts(exps)
    lines += _performance(seconds, exps)
    for name, r in exps.items():
        lines += _header(name, r, command)
        if r.get("kind") in KINDS:
            lines += KINDS[r["kind"]].markdown(r)
        if r.get("notes"):
            lines += [f"- {n}" for n in r["notes"]] + [""]
        lines += _figures(r, report_dir)
    atomic_write_text(path, "\n".join(lines) + "\n")
    return path


def main(argv=None) -> None:
    """``python -m flownav.evaluation.report``: rewrite REPORT.md from results/paper.json (no evaluation)."""
    import argparse

    p = argparse.ArgumentParser(description=main.__doc__)
    p.add_argument("--results", default=str(SHIPPED_RESULTS))
    p.add_argument("--report", default=str(REPO_ROOT / "REPORT.md"))
    a = p.parse_args(argv)
    data = json.loads(Path(a.results).read_text())
    print(write_report(data, Path(a.report), "python -m flownav.evaluation.report", results=Path(a.results)))


if __name__ == "__main__":
    main()
