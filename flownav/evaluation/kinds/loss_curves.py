"""``kind: loss_curves``: the DAgger loss of every student run found, mean +- std over seeds (Fig. 2c)."""

from __future__ import annotations

import json

from flownav.atomic import atomic_write_text
from flownav.evaluation.registry import Missing, register
from flownav.paths import resolve


def markdown(r: dict) -> list[str]:
    c = r.get("curve")
    if not c:
        return []
    early = min(4, len(c["mean"]) - 1)
    return [
        f"{c['runs']} runs; loss (eq. 9) at iteration {c['iteration'][0]:g}: {c['mean'][0]:.3f} +- "
        f"{c['std'][0]:.3f}; at iteration {c['iteration'][early]:g}: {c['mean'][early]:.3f}; final: "
        f"{c['mean'][-1]:.4f} +- {c['std'][-1]:.4f}.",
        "",
    ]


@register("loss_curves", markdown=markdown, policies=lambda spec: [])
def run(suite, name, spec, out) -> dict:
    from flownav.viz.plots import collect_runs, plot_loss_curves

    key = str(spec.get("key", "train/loss"))
    runs = collect_runs([resolve(str(g)) for g in spec.run_globs], key, "iteration")
    if not runs:
        raise Missing(f"no DAgger runs found ({list(spec.run_globs)}): run `{spec.command}`")
    fig, stats = plot_loss_curves(runs, suite.figures_dir / f"{name}.png", key=key)
    if spec.get("json"):
        own = stats | {"files": sorted(runs), "provenance": suite.provenance}
        atomic_write_text(resolve(str(spec.json)), json.dumps(own, indent=1))
    return {"runs": sorted(runs), "curve": stats, "figures": [str(fig)]}
