"""``kind: ratio_sweep``: success against U_swim,max / V_flow,max, reached by scaling the flow's speed as the
paper does (Fig. 6c).

Targets: ``{policy, rises_with_ratio: true, label}`` is met when the policy's success at the highest ratio is
above its success at the lowest and it nowhere falls as the ratio rises, each beyond the two Wilson intervals (the
paper's curve: a weaker swimmer against the flow succeeds less); ``reference`` names a policy whose curve ends the
line also gives.
"""

from __future__ import annotations

from omegaconf import OmegaConf

from flownav.evaluation.registry import register
from flownav.evaluation.tables import pct, ratio_key, sweep_table


def markdown(r: dict) -> list[str]:
    scales = [f"flow x{s:.3g}" for s in r.get("flow_speed_scales", [])]
    return sweep_table(r, r.get("ratios", []), ratio_key, "U_max / V_max", extra=scales)


def verdicts(r: dict) -> list[str]:
    res, lines = r.get("results") or {}, []
    keys = [ratio_key(x) for x in sorted(float(x) for x in r.get("ratios", []))]
    for t in r.get("targets") or []:
        curve = [(k, res[t["policy"]][k]) for k in keys if k in res.get(t["policy"], {})]
        if len(curve) < 2:
            continue
        (k0, first), (k1, last) = curve[0], curve[-1]
        falls = [
            f"{pct(a['success_rate'])} at {ka} to {pct(b['success_rate'])} at {kb}"
            for i, (ka, a) in enumerate(curve)
            for kb, b in curve[i + 1 :]
            if a["success_ci95"][0] > b["success_ci95"][1]
        ]
        rises = last["success_ci95"][0] > first["success_ci95"][1]
        verdict = "met" if rises and not falls else "NOT met" + (f", falls from {falls[0]}" if falls else "")
        ref = res.get(t.get("reference") or "", {})
        also = (
            f"; {t['reference']}: {pct(ref[k0]['success_rate'])} to {pct(ref[k1]['success_rate'])}"
            if k0 in ref and k1 in ref
            else ""
        )
        lines.append(
            f"- {t['label']}: {pct(first['success_rate'])} at U_max / V_max = {k0} to {pct(last['success_rate'])} at "
            f"{k1}{also} -> {verdict} (target: rises with the ratio, nowhere falls beyond the Wilson intervals)."
        )
    return lines


@register("ratio_sweep", markdown=markdown, verdicts=verdicts)
def run(suite, name, spec, out) -> dict:
    base_cfg = OmegaConf.merge(spec.flow, {"speed_scale": 1.0})
    base = suite.flow(base_cfg)
    env_cfg = suite.env_cfg(spec)
    swim_max = float(env_cfg.u_max) * float(env_cfg.get("swim_speed_scale", 1.0))
    ratios = [float(r) for r in spec.ratios]
    scales = [swim_max / (r * base.max_speed) for r in ratios]
    results: dict[str, dict] = {}
    for pol in suite.each_policy(spec, out):
        results[pol] = {}
        for ratio, scale in zip(ratios, scales, strict=True):
            flow = suite.flow(OmegaConf.merge(base_cfg, {"speed_scale": scale}))
            ev = suite.measure(
                name, pol, flow, spec.task, env_cfg, suite.episodes_of(spec, pol), label=f" ratio {ratio:.3f}"
            )
            results[pol][ratio_key(ratio)] = ev.summary | {"flow_speed_scale": scale}
    figures = suite.sweep_figure(name, results, ratios, "U_swim,max / V_flow,max", out["title"], keyfn=ratio_key)
    return {
        "ratios": ratios,
        "flow_speed_scales": scales,
        "base_max_speed": float(base.max_speed),
        "swim_max_speed": swim_max,
        "results": results,
        "figures": figures,
    }
