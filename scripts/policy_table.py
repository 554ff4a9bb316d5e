"""The README's first table ("Which policy to use"), printed from the shipped results: the generalisation suite
(results/generalization.json), the paper's training task and the well-posed ABC test (results/paper.json,
experiments ``training`` and ``abc_periodic``; the oracle's row there is ``oracle_long``, its search for ABC).

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
    "generalist_teacher": "generalist_teacher (PPO, privileged view `geo_priv`)",
    "generalist_student": "**generalist_student** (`ego_mem_grad`)",
    "generalist_student_noisy": "generalist_student_noisy (`ego_mem_grad`, trained with noisy sensors)",
}


def success(rows: dict, policy: str) -> float | None:
    row = rows.get(policy)
    return row["success_rate"] if isinstance(row, dict) and "success_rate" in row else None


def pct(x: float | None) -> str:
    if x is not None and 0 < x < 0.01:  # below 1%: two decimals, so that rare successes do not read as none
        return f"{100 * x:.2f}"
    return "-" if x is None else f"{100 * x:.1f}".removesuffix(".0")


def main() -> None:
    gen = json.loads((REPO_ROOT / "results" / "generalization.json").read_text())
    experiments = json.loads((REPO_ROOT / "results" / "paper.json").read_text())["experiments"]
    paper, abc = experiments["training"], experiments["abc_periodic"]["results"]
    cases, held = gen["results"], gen["summary"]["held_out"]
    analytic_cases = [c for c, m in gen["cases"].items() if m["in_family"] is None and m["flow"]["type"] == "zoo"]

    def rate(case: str, policy: str) -> float | None:
        return success(cases[case], policy)

    header = ["policy", "paper's task (wake)", "still water", "uniform 0.5", "headwind 0.5",
              f"{len(analytic_cases)} held-out analytic flows (mean)", "turned wakes (135, 180)", "wake at 1.35x",
              "extended domain", "well-posed ABC",
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
                 pct(rate("headwind_0.5", p)), pct(mean), turned, pct(rate("wake_x1.35", p)), pct(rate("extended", p)),
                 pct(success(abc, "oracle_long" if p == "oracle" else p)),
                 f"{100 * s['mean_fraction_of_oracle']:.0f}%", beats]  # fmt: skip
        print(f"| {label} | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    main()
