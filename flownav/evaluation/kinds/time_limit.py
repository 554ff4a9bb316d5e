"""``kind: time_limit``: success against the episode's time limit. The paper does not give its limit, and a
deterministic episode is the same up to any limit, so one run at the longest limit answers every shorter one."""

from __future__ import annotations

from omegaconf import OmegaConf

from flownav.evaluation.metrics import summarize, truncate_at
from flownav.evaluation.registry import register
from flownav.evaluation.tables import angle_key, log_line, sweep_table


def markdown(r: dict) -> list[str]:
    return sweep_table(r, r.get("limits", []), angle_key, "time limit")


@register("time_limit", markdown=markdown)
def run(suite, name, spec, out) -> dict:
    flow = suite.flow(spec.flow)
    limits = sorted(float(t) for t in spec.limits)
    env_cfg = OmegaConf.merge(suite.env_cfg(spec), {"time_limit": limits[-1]})
    results: dict[str, dict] = {}
    for pol in suite.each_policy(spec, out):
        ep = suite.rollout(pol, flow, spec.task, env_cfg, suite.episodes_of(spec, pol)).episodes
        results[pol] = {}
        for limit in limits:
            results[pol][angle_key(limit)] = summarize(
                truncate_at(ep.status, ep.time, limit, float(env_cfg.dt)), ep.time
            )
            suite.log(f"[{name}] {pol} limit {limit:g}: {log_line(results[pol][angle_key(limit)])}")
    figures = suite.sweep_figure(name, results, limits, "time limit (time units D/U)", out["title"])
    return {"limits": limits, "results": results, "figures": figures}
