"""``kind: extended``: a fixed target, starts anywhere; success maps over subregions of the start (Fig. 4, SI 2)."""

from __future__ import annotations

from flownav.evaluation.kinds.success import success_verdicts
from flownav.evaluation.metrics import subregion_counts
from flownav.evaluation.registry import register
from flownav.evaluation.tables import success_table


@register("extended", markdown=success_table, verdicts=success_verdicts)
def run(suite, name, spec, out) -> dict:
    flow = suite.flow(spec.flow)
    env_cfg = suite.env_cfg(spec)
    bins = [int(b) for b in spec.get("bins", (10, 10, 10))]
    results, maps, figures = {}, {}, []
    for pol in suite.each_policy(spec, out):
        ev = suite.measure(name, pol, flow, spec.task, env_cfg, suite.episodes_of(spec, pol))
        counts, wins = subregion_counts(ev.episodes.start, ev.episodes.success, flow.bounds, bins)
        results[pol] = ev.summary
        maps[pol] = {"episodes": counts.tolist(), "successes": wins.tolist()}
    if maps:
        from flownav.viz.maps import plot_success_maps

        figures = plot_success_maps(
            maps, flow, list(spec.task.target), suite.figures_dir / f"{name}_success_map", title=out["title"]
        )
    return {
        "results": results,
        "maps": maps,
        "bins": bins,
        "bounds": [flow.bounds.lo, flow.bounds.hi],
        "figures": figures,
    }
