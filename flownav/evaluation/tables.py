"""How a summary (``metrics.summarize``'s dict) is printed: percentages, Wilson intervals, the log line of one
policy, and the REPORT.md tables the experiment kinds share."""

from __future__ import annotations


def pct(x) -> str:
    return "-" if x is None else f"{100 * x:.2f}%"


def ci(s: dict) -> str:
    lo, hi = s["success_ci95"]
    return f"[{100 * lo:.2f}, {100 * hi:.2f}]"


def num(x, fmt="{:.2f}") -> str:
    return "-" if x is None else fmt.format(x)


def log_line(s: dict) -> str:
    """One policy's summary on one line (the suite's log)."""
    lo, hi = s["success_ci95"]
    t = s["mean_success_time"]
    f = s["failures"]
    return (
        f"success {100 * s['success_rate']:.2f}% [{100 * lo:.2f}, {100 * hi:.2f}] of {s['episodes']}, time {t:.2f}"
        if t is not None
        else f"success 0 of {s['episodes']}"
    ) + (f", left {f['left_domain']['count']}, hit {f['hit_obstacle']['count']}, timeout {f['timeout']['count']}")


def success_table(r: dict) -> list[str]:
    """One row per policy: success and time next to the paper's, the failure causes."""
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


def sweep_table(r: dict, xs, keyfn, xname: str, extra=None) -> list[str]:
    """One row per swept value, success and interval of each policy."""
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


def angle_key(a: float) -> str:
    return f"{a:g}"


def ratio_key(r: float) -> str:
    return f"{r:.3f}"
