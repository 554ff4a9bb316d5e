"""``kind: figures``: example episodes of each policy (Figs. 3, 5a-d, 6a and Movie 1).

Three parts, each optional but ``wake``: the training flow (3D trajectories, velocity traces, a movie),
``misaligned`` (the same flow rotated) and ``abc`` (the ABC flow). Every part runs on the entry's ``seed``, so
every policy starts from the same candidate episodes.
"""

from __future__ import annotations

from collections.abc import Mapping

import torch
from omegaconf import OmegaConf

from flownav.envs.navigation import Status
from flownav.evaluation.registry import Missing, register


def pick_episode(runs: dict, prefer: list[str]) -> int:
    """First episode that all preferred policies solve; else the first the last preferred one solves; else 0."""
    wins = {p: runs[p]["status"] == Status.SUCCESS for p in prefer if p in runs}
    if not wins:
        return 0
    options = [torch.stack(list(wins.values())).all(0)] + [wins[p] for p in reversed(list(wins))]
    for ok in options:
        if bool(ok.any()):
            return int(ok.nonzero()[0, 0])
    return 0


def _one_episode(traj: dict, i: int) -> dict:
    return {k: (v if k == "time" else v[i : i + 1]) for k, v in traj.items()}


def _recorded(suite, pol, flow, task_cfg, env_cfg, n: int, seed: int) -> dict:
    return suite.rollout(pol, flow, task_cfg, env_cfg, n, seed=seed, record=n).episodes.trajectories


def _flow_or_none(suite, flow_cfg, out):
    try:
        return suite.flow(flow_cfg)
    except Missing as e:
        out["missing"].append(str(e))
        return None


def wake_figures(suite, name, spec, out, flow, seed: int) -> list:
    """Fig. 3: the policies from one start to one target in the training flow; the movie of one of them."""
    from flownav.viz import trajectories as tv

    wake = spec.wake
    env_cfg = suite.env_cfg(wake)
    n = int(wake.get("candidates", 32))  # the same candidates for every policy: show one the preferred all solve
    cands = {pol: _recorded(suite, pol, flow, wake.task, env_cfg, n, seed) for pol in suite.each_policy(wake, out)}
    if not cands:
        return []
    i = pick_episode(cands, list(wake.get("prefer_success", ["teacher", "student"])))
    runs = {pol: _one_episode(tr, i) for pol, tr in cands.items()}
    out["notes"].append(f"wake figures show candidate episode {i} of {n} (seed {seed})")
    d = suite.figures_dir
    figures = [
        tv.plot_trajectories_3d(
            runs, flow, d / f"{name}_wake_3d.png", title="Training flow: one episode of each policy"
        ),
        tv.plot_velocity_traces(runs, d / f"{name}_velocity_traces.png"),
    ]
    movie_pol = str(wake.get("movie_policy", "student"))
    if movie_pol in runs and spec.get("movie", True):
        title = f"{movie_pol} in the cylinder wake"
        frames = int(spec.get("movie_frames", 60))
        figures.append(tv.make_movie(runs[movie_pol], flow, d / f"{name}_movie.mp4", title=title, frames=frames))
    return figures


def misaligned_figures(suite, name, spec, out, flow, seed: int) -> list:
    """Fig. 5a-d: the policies in the training flow rotated by each angle."""
    from flownav.viz import trajectories as tv

    mis = spec.misaligned
    n = int(mis.get("episodes", 4))
    runs = {}
    for pol in suite.each_policy(mis, out):
        for angle in mis.angles:
            env_cfg = OmegaConf.merge(suite.env_cfg(spec.wake), {"misalignment_deg": float(angle)})
            runs[(pol, float(angle))] = _recorded(suite, pol, flow, spec.wake.task, env_cfg, n, seed)
    return [tv.plot_misaligned(runs, flow, suite.figures_dir / f"{name}_misaligned.png")] if runs else []


def abc_figures(suite, name, spec, out, seed: int) -> list:
    """Fig. 6a: the policies in the ABC flow."""
    from flownav.viz import trajectories as tv

    abc = spec.abc
    flow = _flow_or_none(suite, abc.flow, out)
    if flow is None:
        return []
    n = int(abc.get("episodes", 5))
    env_cfg = suite.env_cfg(abc)
    runs = {pol: _recorded(suite, pol, flow, abc.task, env_cfg, n, seed) for pol in suite.each_policy(abc, out)}
    return [tv.plot_abc(runs, flow, suite.figures_dir / f"{name}_abc.png")] if runs else []


def policies(spec) -> list[str]:
    names = []
    for part in ("wake", "misaligned", "abc"):
        node = spec.get(part)
        if isinstance(node, Mapping) or OmegaConf.is_dict(node):
            names += list(node.get("policies") or [])
    return names


@register("figures", policies=policies)
def run(suite, name, spec, out) -> dict:
    seed = int(spec.get("seed", suite.seed))
    out["notes"] = []
    figures = []
    flow = _flow_or_none(suite, spec.wake.flow, out)
    if flow is not None:
        figures += wake_figures(suite, name, spec, out, flow, seed)
        if spec.get("misaligned") is not None:
            figures += misaligned_figures(suite, name, spec, out, flow, seed)
    if spec.get("abc") is not None:
        figures += abc_figures(suite, name, spec, out, seed)
    return {"figures": [str(f) for f in figures], "notes": out["notes"]}
