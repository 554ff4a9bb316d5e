"""The trajectory figure of a periodic evaluation during training (wandb / TensorBoard image, PNG in the run dir).

ep = run_episodes(policy, obs_key, make_env, episodes, record=4)   # the evaluation records a few episodes
logger.log_figure(step, "eval/trajectories", eval_trajectories_figure(ep.trajectories, flow))
"""

from __future__ import annotations

import matplotlib.pyplot as plt
import numpy as np

from flownav.envs.navigation import Status
from flownav.flows.families import FlowFamily
from flownav.viz.fields import symmetric_levels, xy_slice

STATUS_STYLE = {  # outcome -> line style, so failures stand out at a glance
    Status.SUCCESS: "-",
    Status.LEFT_DOMAIN: "--",
    Status.HIT_OBSTACLE: ":",
    Status.TIMEOUT: "-.",
}


def eval_trajectories_figure(traj: dict, flow, title: str = ""):
    """Top view (x-y) of recorded episodes (``run_episodes(..., record=k).trajectories``) over the z-vorticity
    of the first episode's start plane at its start time; start (dot) and target (star) of each, style by outcome.
    A flow family has no one field to draw (every swimmer has its own flow): its figure has the paths alone."""
    episodes = traj["position"].shape[0]
    b = flow.bounds
    fig, ax = plt.subplots(figsize=(6.4, 6.4 * (b.hi[1] - b.lo[1]) / (b.hi[0] - b.lo[0]) + 0.6))
    if not isinstance(flow, FlowFamily):
        z0, t0 = float(traj["position"][0, 0, 2]), float(traj["t0"][0])
        X, Y, _, om = xy_slice(flow, z0, t0, (b.lo[0], b.hi[0], b.lo[1], b.hi[1]), (120, 72))
        om, levels = symmetric_levels(om)
        cs = ax.contourf(X, Y, om, levels=levels, cmap="RdBu_r", alpha=0.8)
        fig.colorbar(cs, ax=ax, label="omega_z D / U", fraction=0.03, pad=0.02, format="%.2g")
    for ob in getattr(flow, "obstacles", ()):
        ax.add_patch(plt.Circle(ob.center, ob.radius, color="0.3"))
    outcomes = set()
    for i in range(episodes):
        path = traj["position"][i].numpy()[traj["alive"][i].numpy()]
        status = Status(int(traj["status"][i]))
        outcomes.add(status)
        color = f"C{i}"
        ax.plot(path[:, 0], path[:, 1], STATUS_STYLE.get(status, "-"), color=color, lw=1.6)
        ax.plot(path[0, 0], path[0, 1], "o", color=color, mec="k", ms=5)
        tgt = traj["target"][i].numpy()
        ax.plot(tgt[0], tgt[1], "*", color=color, mec="k", ms=12)
    for status in sorted(outcomes):
        ax.plot([], [], STATUS_STYLE.get(status, "-"), color="k", label=status.name.lower())
    ax.legend(fontsize=7, loc="upper right")
    ax.set_xlim(b.lo[0], b.hi[0])
    ax.set_ylim(b.lo[1], b.hi[1])
    ax.set_aspect("equal")
    ax.set_xlabel("x / D")
    ax.set_ylabel("y / D")
    success = np.mean([int(s) == Status.SUCCESS for s in traj["status"]])
    ax.set_title(title or f"{episodes} evaluation episodes ({success:.0%} success)", fontsize=9)
    fig.tight_layout()
    return fig
