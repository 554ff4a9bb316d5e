"""REPORT.md's Targets section: each kind judges its entry's targets exactly, and the shipped report judges every
target the configs declare."""

from __future__ import annotations

import json

from omegaconf import OmegaConf

from flownav.evaluation.kinds.ratio_sweep import verdicts as sweep_verdicts
from flownav.evaluation.kinds.success import success_verdicts
from flownav.evaluation.kinds.zoo import zoo_verdicts
from flownav.evaluation.metrics import wilson_interval
from flownav.paths import REPO_ROOT


def rate(successes: int, episodes: int = 100) -> dict:
    lo, hi = wilson_interval(successes, episodes)
    return {"success_rate": successes / episodes, "success_ci95": [lo, hi], "episodes": episodes}


ZOO = {
    "margin": 0.02,
    "cases": {"current": {"in_family": "uniform_currents"}, "gyre": {"in_family": None}, "vortex": {}},
    "results": {
        "current": {"p": rate(97), "head_to_target": rate(100), "oracle": rate(100)},
        "gyre": {"p": rate(89), "head_to_target": rate(90), "oracle": rate(100)},
        "vortex": {"p": rate(3), "head_to_target": rate(0), "oracle": rate(10)},
    },
}


def zoo_lines(*targets) -> list[str]:
    return zoo_verdicts(ZOO | {"targets": [t | {"policy": "p", "label": "L"} for t in targets]})


def test_zoo_targets_hold_on_every_held_out_case_or_name_where_not():
    assert zoo_lines({"beats_reference": True}) == ["- L: 2 of 2 cases >= head_to_target's success - 2 points -> met."]
    assert zoo_lines({"min_fraction_of_oracle": 0.8}) == [
        "- L: 1 of 2 cases >= 80% of the oracle's success -> NOT met, short on vortex 3.00% vs the oracle's 10.00%."
    ]


def test_a_zoo_target_over_named_cases_counts_those_cases_only():
    assert zoo_lines({"cases": ["current", "gyre"], "min_success": 0.99}) == [
        "- L: 0 of 2 cases >= 99% -> NOT met, short on current 97.00%; gyre 89.00%."
    ]
    assert zoo_lines({"cases": ["current"], "beats_reference": True}) == [
        "- L: 0 of 1 cases >= head_to_target's success - 2 points -> NOT met, short on current 97.00% vs the "
        "head_to_target's 100.00%."
    ]


def sweep(*successes: int) -> dict:
    ratios = [0.1 * (i + 1) for i in range(len(successes))]
    curve = {f"{r:.3f}": rate(s, 1000) for r, s in zip(ratios, successes, strict=True)}
    target = {"policy": "p", "rises_with_ratio": True, "label": "L"}
    return {"ratios": ratios, "results": {"p": curve, "o": curve}, "targets": [target]}


def test_a_curve_rising_with_the_ratio_meets_the_fig_6c_target():
    assert sweep_verdicts(sweep(0, 20, 19, 80)) == [
        "- L: 0.00% at U_max / V_max = 0.100 to 8.00% at 0.400 -> met (target: rises with the ratio, nowhere falls "
        "beyond the Wilson intervals)."
    ]


def test_a_fall_or_a_flat_curve_does_not_meet_it():
    (line,) = sweep_verdicts(sweep(0, 80, 20, 90))
    assert "-> NOT met, falls from 8.00% at 0.200 to 2.00% at 0.300 " in line
    assert "-> NOT met (target" in sweep_verdicts(sweep(5, 5, 6, 5))[0]


def test_the_sweep_line_gives_the_reference_curve_ends():
    r = sweep(0, 80)
    r["targets"][0]["reference"] = "o"
    assert "8.00% at 0.200; o: 0.00% to 8.00% -> met" in sweep_verdicts(r)[0]


def test_a_fraction_of_another_policy_is_met_or_not_by_min_fraction():
    r = {"results": {"p": rate(70), "o": rate(80)}}
    target = {"policy": "p", "against": "o", "label": "L"}
    assert success_verdicts(r | {"targets": [target | {"min_fraction": 0.8}]}) == [
        "- L: 70.00% vs 80.00%, the p keeps 88% of the o's success -> met (target >= 80%)."
    ]
    assert success_verdicts(r | {"targets": [target | {"min_fraction": 0.9}]})[0].endswith(
        "-> NOT met (target >= 90%)."
    )
    assert success_verdicts(r | {"targets": [target]}) == ["- L: 70.00% vs 80.00%, the p keeps 88% of the o's success."]


def test_the_shipped_report_judges_every_target_the_configs_declare():
    """Each target of an experiment in results/paper.json has its line in REPORT.md: a target added to a config
    reaches the report by rerunning its experiment (the suites' ship=true command)."""
    shipped = json.loads((REPO_ROOT / "results" / "paper.json").read_text())["experiments"]
    report = (REPO_ROOT / "REPORT.md").read_text()
    for path in sorted((REPO_ROOT / "conf" / "evaluate" / "experiment").glob("*.yaml")):
        for name, entry in (OmegaConf.load(path).get("suite") or {}).items():
            if name not in shipped or shipped[name].get("skipped"):
                continue
            for target in entry.get("targets") or []:
                missing = f"{path.name}: {name}'s target {target.label!r} is not in REPORT.md"
                assert f"- {target.label}: " in report, missing
