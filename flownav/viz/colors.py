"""One colour per policy, the same in every figure."""

from __future__ import annotations

# The paper's three policies keep their colours; our students get their own, so that curves of several
# students in one figure stay apart. Other names (teacher_symmetric, ...) fall back to their role's colour.
POLICY_COLORS = {
    "teacher": "tab:blue",
    "student": "tab:orange",
    "baseline": "tab:gray",
    "student_up": "tab:green",
    "student_mem": "tab:red",
    "teacher_robust": "tab:cyan",
    "student_robust": "tab:purple",
    "student_mem_robust": "tab:brown",
    "generalist_teacher": "navy",
    "generalist_student": "magenta",
    "head_to_target": "tab:pink",
    "passive": "black",
    "oracle": "tab:olive",
    "oracle_long": "tab:olive",
}


def policy_color(name: str, i: int = 0) -> str:
    name = str(name)
    return POLICY_COLORS.get(name) or POLICY_COLORS.get(name.split("_")[0], f"C{i}")


# Markers that tell overlapping curves of several policies apart (the i-th policy of a figure).
MARKERS = ("o", "s", "^", "D", "v", "P", "X", "h")
