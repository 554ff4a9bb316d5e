"""The README's first table ("Which policy to use"), printed from the shipped results: the generalisation suite
(results/generalization.json) and the paper's training task (results/paper.json, experiment ``training``).

    python scripts/policy_table.py
"""

from __future__ import annotations

import json

from flownav.paths import REPO_ROOT

# The README's rows, in order, with their labels.
POLICIES = {
    "head_to_target": "head-to-target",
    "oracle": "oracle",
    "teacher": "teacher (paper)",
    "student": "student (paper)",
    "baseline": "baseline (paper: PPO on the ego view)",
    "student_robust": "student_robust",
    "generalist_student": "**generalist_student** (`ego_mem_grad`)",
    "generalist_student_noisy": "generalist_student_noisy (`ego_mem_grad`, trained with noisy sensors)",
}


def success(rows: dict, policy: str) -> float | None:
    row = rows.get(policy)
    return row["success_rate"] if isinstance(row, dict) and "success_rate" in row else None


def pct(x: float | None) -> str:
    return "-" if x is None else f"{100 * x:.1f}".removesuffix(".0")


def main() -> None:
    gen = json.loads((REPO_ROOT / "results" / "generalization.json").read_text())
    paper = json.loads((REPO_ROOT / "results" / "paper.json").read_text())["experiments"]["training"]
    cases, held = gen["results"], gen["summary"]["held_out"]
    analytic_cases = [c for c, m in gen["cases"].items() if m["in_family"] is None and m["flow"]["type"] == "zoo"]

    def rate(case: str, policy: str) -> float | None:
        return success(cases[case], policy)

    header = ["policy", "paper's task (wake)", "still water", "uniform 0.5", "headwind 0.5",
              f"{len(analytic_cases)} held-out analytic flows (mean)", "turned wakes (135, 180)", "extended domain",
              f"mean fraction of the oracle, {held['oracle']['cases']} held-out cases",
              "beats head-to-target (held-out)"]  # fmt: skip
    print("| " + " | ".join(header) + " |")
    print("|" + "---|" * len(header))
    for p, label in POLICIES.items():
        analytic = [rate(c, p) for c in analytic_cases]
        mean = sum(analytic) / len(analytic) if None not in analytic else None
        s = held[p]
        beats = "-" if p in ("head_to_target", "oracle") else f"{s['beats_head_to_target']} of {s['cases']}"
        turned = f"{pct(rate('wake_turned_135', p))}, {pct(rate('wake_turned_180', p))}"
        cells = [pct(success(paper["results"], p)), pct(rate("still_water", p)), pct(rate("uniform_x_0.5", p)),
                 pct(rate("headwind_0.5", p)), pct(mean), turned, pct(rate("extended", p)),
                 f"{100 * s['mean_fraction_of_oracle']:.0f}%", beats]  # fmt: skip
        print(f"| {label} | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    main()
