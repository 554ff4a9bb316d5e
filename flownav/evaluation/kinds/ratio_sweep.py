"""``kind: ratio_sweep``: success against U_swim,max / V_flow,max, reached by scaling the flow's speed as the
paper does (Fig. 6c)."""

from __future__ import annotations

from omegaconf import OmegaConf

from flownav.evaluation.registry import register
from flownav.evaluation.tables import ratio_key, sweep_table


def markdown(r: dict) -> list[str]:
    scales = [f"flow x{s:.3g}" for s in r.get("flow_speed_scales", [])]
    return sweep_table(r, r.get("ratios", []), ratio_key, "U_max / V_max", extra=scales)


@register("ratio_sweep", markdown=markdown)
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
