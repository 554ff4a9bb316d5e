"""``kind: misalignment``: the scene rotated about z by each of ``angles`` (Fig. 5e).

Targets: ``{policy, max_spread, label}`` is met when the policy's success over the angles spans at most
``max_spread``; ``{policy, label}`` alone reports its success at the first angle and at the worst one.
"""

from __future__ import annotations

from omegaconf import OmegaConf

from flownav.evaluation.registry import register
from flownav.evaluation.tables import angle_key, pct, sweep_table


def markdown(r: dict) -> list[str]:
    return sweep_table(r, r.get("angles", []), angle_key, "angle (deg)")


def verdicts(r: dict) -> list[str]:
    res, lines = r.get("results") or {}, []
    for t in r.get("targets") or []:
        rates = [v["success_rate"] for v in (res.get(t["policy"]) or {}).values()]
        if not rates:
            continue
        if "max_spread" in t:
            spread = max(rates) - min(rates)
            met = "met" if spread <= float(t["max_spread"]) else "NOT met"
            lines.append(
                f"- {t['label']}: {pct(min(rates))} to {pct(max(rates))}, spread {100 * spread:.2f} points -> {met} "
                f"(target: within {100 * float(t['max_spread']):g} points)."
            )
        else:
            lines.append(f"- {t['label']}: {pct(rates[0])} at the first angle, {pct(min(rates))} at worst.")
    return lines


@register("misalignment", markdown=markdown, verdicts=verdicts)
def run(suite, name, spec, out) -> dict:
    flow = suite.flow(spec.flow)
    angles = [float(a) for a in spec.angles]
    results: dict[str, dict] = {}
    for pol in suite.each_policy(spec, out):
        results[pol] = {}
        for angle in angles:
            env_cfg = OmegaConf.merge(suite.env_cfg(spec), {"misalignment_deg": angle})
            ev = suite.measure(
                name, pol, flow, spec.task, env_cfg, suite.episodes_of(spec, pol), label=f" {angle:g} deg"
            )
            results[pol][angle_key(angle)] = ev.summary
    figures = suite.sweep_figure(name, results, angles, "misalignment angle (deg)", out["title"])
    return {"angles": angles, "results": results, "figures": figures}
