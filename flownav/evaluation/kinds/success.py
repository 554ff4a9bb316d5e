"""``kind: success``: the success table of each policy on one flow, task and env (training flow, ABC, SI 1).

Targets (``targets`` in the entry): ``{policy, min_success, label}`` is met when the policy's success is at
least ``min_success``; ``{policy, against, label}`` says how much of ``against``'s success the policy keeps
(with the paper's ratio when the entry's ``paper`` has both), met when that is at least ``min_fraction`` if given;
``{policy, reference, label}`` is a diagnostic line, the policy's success next to the reference's.
"""

from __future__ import annotations

from flownav.evaluation.registry import register
from flownav.evaluation.tables import pct, success_table


def success_verdicts(r: dict) -> list[str]:
    res, paper, lines = r.get("results") or {}, r.get("paper") or {}, []
    for t in r.get("targets") or []:
        pol = t["policy"]
        if pol not in res:
            continue
        s = res[pol]["success_rate"]
        ps = (paper.get(pol) or {}).get("success")
        if "min_success" in t:
            target = float(t["min_success"])
            met = "met" if s >= target else "NOT met"
            on_paper = "" if ps is None else f", paper {ps:g}%"
            lines.append(f"- {t['label']}: {pct(s)} -> {met} (target >= {100 * target:g}%{on_paper}).")
        elif "against" in t:
            other = res.get(t["against"])
            if other is None or other["success_rate"] <= 0:
                continue
            o = other["success_rate"]
            po = (paper.get(t["against"]) or {}).get("success")
            on_paper = "" if ps is None or not po else f" (paper: {ps:g}% vs {po:g}%, {100 * ps / po:.1f}%)"
            verdict = ""
            if "min_fraction" in t:
                target = float(t["min_fraction"])
                verdict = f" -> {'met' if s >= target * o else 'NOT met'} (target >= {100 * target:g}%)"
            lines.append(
                f"- {t['label']}: {pct(s)} vs {pct(o)}, the {pol} keeps {100 * s / o:.0f}% of the "
                f"{t['against']}'s success{on_paper}{verdict}."
            )
        elif "reference" in t:
            ref = (res.get(t["reference"]) or {}).get("success_rate")
            lines.append(f"- {t['label']}: {pct(s)}" + ("." if ref is None else f", {t['reference']} {pct(ref)}."))
    return lines


@register("success", markdown=success_table, verdicts=success_verdicts)
def run(suite, name, spec, out) -> dict:
    flow = suite.flow(spec.flow)
    env_cfg = suite.env_cfg(spec)
    results = {}
    for pol in suite.each_policy(spec, out):
        results[pol] = suite.measure(name, pol, flow, spec.task, env_cfg, suite.episodes_of(spec, pol)).summary
    return {"results": results, "flow_max_speed": float(flow.max_speed)}
