"""``results/paper.json`` (machine-readable, keyed by experiment) and ``REPORT.md`` (the paper's numbers
side by side with ours, Wilson intervals, the command and git commit that produced each table)."""

from __future__ import annotations

import json
import os
import platform
import subprocess
import time
from pathlib import Path

from flownav.atomic import atomic_write_text
from flownav.paths import REPO_ROOT

TARGETS = (
    "Targets (reported, not asserted): student >= 95% in the training flow; student within 3 points across all "
    "misalignment angles while the teacher falls; ABC student >= 76%."
)


def git_commit(root: Path = REPO_ROOT) -> str:
    """HEAD, with ``+dirty`` when tracked files differ from it (other engineers edit the same checkout)."""
    try:
        sha = subprocess.run(["git", "rev-parse", "HEAD"], cwd=root, capture_output=True, text=True, check=True)
        dirty = subprocess.run(
            ["git", "status", "--porcelain", "--untracked-files=no"],
            cwd=root,
            capture_output=True,
            text=True,
            check=True,
        )
        return sha.stdout.strip()[:12] + ("+dirty" if dirty.stdout.strip() else "")
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


def provenance(command: str) -> dict:
    return {
        "command": command,
        "commit": git_commit(),
        "date_utc": time.strftime("%Y-%m-%d %H:%M:%S", time.gmtime()),
        "host": f"{platform.machine()} {os.cpu_count()} cores, {platform.python_version()}",
    }


def merge_results(path: Path, new: dict, prov: dict) -> dict:
    """Update ``path`` (results/paper.json) with the experiments just run; keep the others."""
    path = Path(path)
    old = {}
    if path.is_file():
        try:
            old = json.loads(path.read_text())
        except json.JSONDecodeError:
            old = {}
    experiments = dict(old.get("experiments", {}))
    for name, res in new.items():
        experiments[name] = res | {"provenance": prov}
    data = {"format": "flownav-paper-results-v1", "experiments": experiments}
    atomic_write_text(path, json.dumps(data, indent=1, default=_json_default))
    return data


def _json_default(o):
    if hasattr(o, "tolist"):
        return o.tolist()
    return str(o)


# ----------------------------------------------------------------------------- markdown
def pct(x) -> str:
    return "-" if x is None else f"{100 * x:.2f}%"


def ci(s: dict) -> str:
    lo, hi = s["success_ci95"]
    return f"[{100 * lo:.2f}, {100 * hi:.2f}]"


def num(x, fmt="{:.2f}") -> str:
    return "-" if x is None else fmt.format(x)


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


def _success_table(r: dict) -> list[str]:
    res = r.get("results") or {}
    if not res:
        return []
    paper = r.get("paper") or {}
    lines = [
        "| policy | success (paper) | success (ours) | Wilson 95% CI | mean success time (paper) | ours | "
        "left domain | hit cylinder | out of time | episodes |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for pol, s in res.items():
        p = paper.get(pol) or {}
        ps = p.get("success")
        f = s["failures"]
        lines.append(
            f"| {pol} | {'-' if ps is None else f'{ps:.2f}%'} | {pct(s['success_rate'])} | {ci(s)} | "
            f"{num(p.get('time'))} | {num(s['mean_success_time'])} | {pct(f['left_domain']['rate'])} | "
            f"{pct(f['hit_obstacle']['rate'])} | {pct(f['timeout']['rate'])} | {s['episodes']} |"
        )
    return lines + [""]


def _sweep_table(r: dict, xs, keyfn, xname: str, extra=None) -> list[str]:
    res = r.get("results") or {}
    if not res:
        return []
    pols = list(res)
    head = f"| {xname} | " + " | ".join(f"{p} success | {p} 95% CI" for p in pols) + " |"
    lines = [head, "|---|" + "---|---|" * len(pols)]
    for i, x in enumerate(xs):
        cells = []
        for p in pols:
            s = res[p].get(keyfn(x))
            cells += [pct(s["success_rate"]), ci(s)] if s else ["-", "-"]
        label = f"{x:g}" if extra is None else f"{x:.3f} ({extra[i]})"
        lines.append(f"| {label} | " + " | ".join(cells) + " |")
    first = next(iter(next(iter(res.values())).values()))
    return lines + ["", f"{first['episodes']} episodes per {xname.split(' ')[0]} and policy.", ""]


def _figures(r: dict, report_dir: Path) -> list[str]:
    out = []
    for f in r.get("figures", []) or []:
        image = "!" if Path(f).suffix in (".png", ".gif", ".jpg", ".svg") else ""  # a movie is a plain link
        out.append(f"{image}[{Path(f).stem}]({_rel(f, report_dir)})")
    return out + [""] if out else []


def _verdicts(exps: dict) -> list[str]:
    lines = ["## Targets", "", TARGETS, ""]
    tr = exps.get("training", {}).get("results", {})
    if "student" in tr:
        s = tr["student"]["success_rate"]
        lines.append(
            f"- Student in the training flow: {pct(s)} -> {'met' if s >= 0.95 else 'NOT met'} (target >= 95%)."
        )
        if "teacher" in tr and tr["teacher"]["success_rate"] > 0:
            t = tr["teacher"]["success_rate"]
            lines.append(
                f"- Student against its teacher: {pct(s)} vs {pct(t)}, the student keeps {100 * s / t:.0f}% of the "
                f"teacher's success (paper: 94.44% vs 94.69%, 99.7%)."
            )
    mis = exps.get("misalignment", {}).get("results", {})
    if "student" in mis:
        rates = [v["success_rate"] for v in mis["student"].values()]
        spread = 100 * (max(rates) - min(rates))
        lines.append(
            f"- Student over misalignment angles: {pct(min(rates))} to {pct(max(rates))}, spread {spread:.2f} points "
            f"-> {'met' if spread <= 3 else 'NOT met'} (target: within 3 points)."
        )
    if "teacher" in mis:
        rates = list(mis["teacher"].values())
        lines.append(
            f"- Teacher over misalignment angles: {pct(rates[0]['success_rate'])} at the first angle, "
            f"{pct(min(v['success_rate'] for v in rates))} at worst (the paper: falls fast with the angle)."
        )
    abc = exps.get("abc", {}).get("results", {})
    if "student" in abc:
        s = abc["student"]["success_rate"]
        lines.append(f"- ABC student: {pct(s)} -> {'met' if s >= 0.76 else 'NOT met'} (target >= 76%, paper 75.9%).")
    still = exps.get("still_water", {}).get("results", {})
    if "student" in still:
        ref = still.get("head_to_target", {}).get("success_rate")
        s = still["student"]["success_rate"]
        lines.append(
            f"- Not a target, a diagnostic for the transfer: in still water the student reaches {pct(s)}"
            + (f", swimming straight at the target {pct(ref)}." if ref is not None else ".")
        )
    if len(lines) == 4:
        lines.append("- No result to compare yet (checkpoints missing).")
    return lines + [""]


def _performance(seconds: float | None, exps: dict) -> list[str]:
    lines = ["## Performance", ""]
    if seconds is not None:
        lines.append(f"- This run of `evaluate.py`: {seconds / 60:.1f} minutes (goal for the whole suite: <= 60).")
    total = sum(float(r.get("seconds") or 0) for r in exps.values())
    lines.append(
        f"- The experiments below, as last run, took {total / 60:.1f} minutes together (the per-experiment times "
        "are in each section; goal for `+experiment=paper`: <= 60 minutes)."
    )
    bench = REPO_ROOT / "benchmarks" / "results" / "eval_throughput.json"
    if bench.is_file():
        try:
            lines.append(f"- `python benchmarks/eval_throughput.py`: {json.loads(bench.read_text())['headline']}.")
        except (json.JSONDecodeError, KeyError):
            pass
    return lines + [""]


def write_report(data: dict, path: Path, command: str, seconds: float | None = None, commit: str | None = None) -> Path:
    """REPORT.md from the merged results (every experiment run so far); ``commit``: the code that ran (default HEAD)."""
    path = Path(path)
    report_dir = path.parent
    exps = data.get("experiments", {})
    lines = [
        "# flownav: the paper's experiments, reproduced",
        "",
        "Written by `python evaluate.py +experiment=paper` (flownav/evaluation/report.py); this run: "
        f"`{command}` at commit `{commit or git_commit()}`, {time.strftime('%Y-%m-%d %H:%M', time.gmtime())} UTC. "
        "Machine-readable results: `results/paper.json`. How to run each experiment: `docs/evaluation.md`.",
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
        kind = r.get("kind")
        if kind in ("success", "extended"):
            lines += _success_table(r)
        elif kind == "misalignment":
            lines += _sweep_table(r, r.get("angles", []), lambda a: f"{a:g}", "angle (deg)")
        elif kind == "time_limit":
            lines += _sweep_table(r, r.get("limits", []), lambda t: f"{t:g}", "time limit")
        elif kind == "ratio_sweep":
            scales = [f"flow x{s:.3g}" for s in r.get("flow_speed_scales", [])]
            lines += _sweep_table(r, r.get("ratios", []), lambda x: f"{x:.3f}", "U_max / V_max", extra=scales)
        elif kind == "zoo":
            from flownav.evaluation.generalization import zoo_markdown

            lines += zoo_markdown(r)
        elif kind == "loss_curves" and r.get("curve"):
            c = r["curve"]
            lines += [
                f"{c['runs']} runs; loss (eq. 9) at iteration {c['iteration'][0]:g}: {c['mean'][0]:.3f} +- "
                f"{c['std'][0]:.3f}; at iteration {c['iteration'][min(4, len(c['mean']) - 1)]:g}: "
                f"{c['mean'][min(4, len(c['mean']) - 1)]:.3f}; final: "
                f"{c['mean'][-1]:.4f} +- {c['std'][-1]:.4f} (paper: 0.8 -> 0.15 within five iterations, then flat).",
                "",
            ]
        if r.get("notes"):
            lines += [f"- {n}" for n in r["notes"]] + [""]
        lines += _figures(r, report_dir)
    atomic_write_text(path, "\n".join(lines) + "\n")
    return path


def main(argv=None) -> None:
    """``python -m flownav.evaluation.report``: rewrite REPORT.md from results/paper.json (no evaluation)."""
    import argparse

    p = argparse.ArgumentParser(description=main.__doc__)
    p.add_argument("--results", default=str(REPO_ROOT / "results" / "paper.json"))
    p.add_argument("--report", default=str(REPO_ROOT / "REPORT.md"))
    a = p.parse_args(argv)
    data = json.loads(Path(a.results).read_text())
    print(write_report(data, Path(a.report), "python -m flownav.evaluation.report"))


if __name__ == "__main__":
    main()
