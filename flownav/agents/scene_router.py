"""A privileged teacher made of two: the paper's teacher in the paper's scene, the generalist teacher elsewhere.

The generalist PPO teacher (``geo_priv``) learns little of the wake crossing: the paper's task is a small share of
its families. The paper's teacher (``geo_sincos``) crosses that wake in 99% of episodes and fails elsewhere.
:class:`SceneRoutedTeacher` reads ``geo_priv_scene`` (``geo_priv`` plus the simulator's flag "this swimmer is in the
paper's training task as posed", flownav.envs.core.paper_scene) and lets each act where it is good, so that a DAgger
student over the families imitates the better teacher of each scene. Episodes of that scene which start upstream of
the paper's regions (flag 2: the extended domain, ``task.posed_wake_any_start_share``) go to the flow-compensating
expert (flownav/agents/flow_compensating.py), which reaches the target from there where the paper's teacher mostly
does not. The crossing the other way (flag 3: Region 2 to Region 1, ``task.posed_wake_reverse_share``) goes to an
expert of that crossing when one is given (``algo.scene_reverse_expert``, e.g. the paper's SI-2 teacher
``checkpoints/teacher_symmetric.pt``, or a ``geo_priv`` or ``geo_priv_wake`` network), else to the generalist.
Episodes of the paper's target from any other start (flag 4: the rest of the extended domain,
``posed_wake_any_start_box`` beyond x = 4) go to ``algo.scene_away_expert`` when one is given (a ``geo_priv``
checkpoint, e.g. a network that imitates the oracle there: +experiment=generalist_away_expert), else to the paper's
teacher. Every other episode in a flow of the families with an obstacle (flag 5: a CFD wake or a vortex street,
turned, scaled or on a current) goes to ``algo.scene_wake_expert`` when one is given (a ``geo_priv`` or
``geo_priv_wake`` checkpoint, e.g. a network that imitates the oracle over the wake family in the wake's own frame:
+experiment=generalist_wake_expert_turned), else to the generalist; so do the paper's regions in those flows (flag
9) unless ``algo.scene_wake_regions_expert`` is given (a ``geo_priv`` or ``geo_priv_wake`` network that imitates
the oracle on the paper's regions in the turned wakes: +experiment=generalist_wake_regions_expert[_strengths]), and
any other task in the wake as posed (flag 7) unless ``algo.scene_posed_expert`` is given (a ``geo_priv`` network
that imitates the oracle there: +experiment=generalist_posed_expert). Only full-speed swimmers are flagged there (a
weaker swimmer's wake episode keeps flag 0). Episodes in a uniform current or still water of the families (flag 6) go
to the flow-compensating expert with ``algo.scene_currents=all`` (there it swims the straight, fastest track), only
the mostly vertical ones (|u_z| > |u_xy|) with ``algo.scene_currents=vertical``, else to the generalist. Full-speed
episodes in the families' other flows (flag 8: random flows, and those on a current) go to the flow-compensating
expert with ``algo.scene_free_flows=compensating`` (there it beats the generalist at full speed), or the same expert
with its fight against the cross flow capped with ``capped``, else to the generalist. The paper's scene itself may go
to a ``geo_priv`` or ``geo_priv_wake`` network instead of the paper's teacher (``algo.scene_expert``), so that one
expert labels the paper's regions in the posed and the other wakes alike.
"""

from __future__ import annotations

import torch
from torch import nn

from flownav.agents.flow_compensating import FlowCompensating
from flownav.envs.core import (
    SCENE_AWAY,
    SCENE_CURRENT,
    SCENE_FREE,
    SCENE_PAPER,
    SCENE_POSED,
    SCENE_REVERSE,
    SCENE_UPSTREAM,
    SCENE_WAKE,
    SCENE_WAKE_REGIONS,
)
from flownav.envs.observations import GEO_PRIV_FLOW, observation_size, turn_geo_priv
from flownav.errors import CheckpointError
from flownav.rows import route_rows

ROUTED_VIEW = "geo_priv_scene"
GENERALIST_VIEW = "geo_priv"
TURNED_BACK_VIEW = "geo_priv_wake"  # geo_priv in the frame of the swimmer's flow as posed
EXPERT_VIEW = "geo_sincos"
ACTION_SIZE = 3  # (U, dtheta, dpsi): flownav.envs.core.action_bounds
# The views each expert may read (its checkpoint records which).
EXPERT_VIEWS = {
    "scene_expert": (EXPERT_VIEW, GENERALIST_VIEW, TURNED_BACK_VIEW),
    "scene_reverse_expert": (EXPERT_VIEW, GENERALIST_VIEW, TURNED_BACK_VIEW),
    "scene_away_expert": (GENERALIST_VIEW, TURNED_BACK_VIEW),
    "scene_wake_expert": (GENERALIST_VIEW, TURNED_BACK_VIEW),
    "scene_posed_expert": (GENERALIST_VIEW, TURNED_BACK_VIEW),
    "scene_wake_regions_expert": (GENERALIST_VIEW, TURNED_BACK_VIEW),
}
CURRENT_ROUTES = (None, "all", "vertical")  # algo.scene_currents: which currents the flow-compensating expert labels
# The capped expert's least share of its speed towards the target: of 0.3 / 0.5 / 0.7, 0.3 and 0.5 are at or above
# both head-to-target and the uncapped expert in every regime of the families, 0.5 ahead in four of six
# (python scripts/compensation_cap.py).
CAPPED_MIN_PROGRESS = 0.5
# algo.scene_free_flows: the flow-compensating expert that labels the families' other flows at full speed, by its
# min_progress (None: the generalist labels them)
FREE_MIN_PROGRESS = {"compensating": 0.0, "capped": CAPPED_MIN_PROGRESS}
FREE_ROUTES = (None, *FREE_MIN_PROGRESS)


class SceneRoutedTeacher(nn.Module):
    """The expert of each row's paper-scene code (the view's last entry, flownav.envs.core.paper_scene):
    ``expert`` for SCENE_PAPER, the flow-compensating expert for SCENE_UPSTREAM, ``reverse`` (if given) for
    SCENE_REVERSE, ``away`` (if given; else ``expert``) for SCENE_AWAY, ``wake`` (if given) for SCENE_WAKE, ``posed``
    (if given; else as SCENE_WAKE) for SCENE_POSED, ``wake_regions`` (if given; else as SCENE_WAKE) for
    SCENE_WAKE_REGIONS, the
    flow-compensating expert for SCENE_CURRENT if ``currents`` is ``"all"`` (only where the current is mostly
    vertical if ``"vertical"``), the flow-compensating expert for SCENE_FREE if ``free_flows`` is ``"compensating"``
    (capped at :data:`CAPPED_MIN_PROGRESS` if ``"capped"``),
    ``generalist`` elsewhere. Each expert reads the view ``views`` names for it (by default ``expert`` and
    ``reverse`` ``geo_sincos``, the view's first 9 numbers, as ``geo_priv`` begins with it; the others ``geo_priv``,
    all but the turn and the code); ``geo_priv_wake`` is that ``geo_priv`` turned back by the turn."""

    def __init__(
        self,
        generalist: nn.Module,
        expert: nn.Module,
        u_max: float = 1.0,
        reverse: nn.Module | None = None,
        away: nn.Module | None = None,
        wake: nn.Module | None = None,
        currents: str | None = None,
        posed: nn.Module | None = None,
        free_flows: str | None = None,
        wake_regions: nn.Module | None = None,
        views: dict[str, str] | None = None,
    ):
        super().__init__()
        self.views = {"expert": EXPERT_VIEW, "reverse": EXPERT_VIEW} | (views or {})
        if bad := {k: v for k, v in self.views.items() if v not in (EXPERT_VIEW, GENERALIST_VIEW, TURNED_BACK_VIEW)}:
            raise ValueError(f"views names a view the routed teacher cannot feed: {bad}")
        self.generalist, self.expert, self.reverse, self.away, self.wake = generalist, expert, reverse, away, wake
        self.posed, self.wake_regions = posed, wake_regions
        if currents not in CURRENT_ROUTES:
            raise ValueError(f"currents is {currents!r}; choose one of {CURRENT_ROUTES}")
        if free_flows not in FREE_ROUTES:
            raise ValueError(f"free_flows is {free_flows!r}; choose one of {FREE_ROUTES}")
        self.currents = currents
        self.upstream = FlowCompensating(u_max)
        self.free = None if free_flows is None else FlowCompensating(u_max, min_progress=FREE_MIN_PROGRESS[free_flows])
        self.expert_size = observation_size(EXPERT_VIEW)

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        # Each row has one labeller, which runs on its rows only: every expert's MLP on every row would take most of
        # the teacher's time.
        code, view, turn = obs[:, -1].round(), obs[:, :-2], obs[:, -2]
        inputs = {
            EXPERT_VIEW: lambda rows: obs[rows, : self.expert_size],
            GENERALIST_VIEW: lambda rows: view[rows],
            TURNED_BACK_VIEW: lambda rows: turn_geo_priv(view[rows], turn[rows]),
        }
        routes = [*self._routes(code, view), (None, self.generalist, "generalist")]
        choice = torch.full(code.shape, len(routes) - 1, device=code.device)  # no route: the generalist
        for j in reversed(range(len(routes) - 1)):  # the first route that takes a row labels it
            choice = torch.where(routes[j][0], j, choice)

        def label(j: int, rows: torch.Tensor) -> torch.Tensor:
            _, labeller, name = routes[j]
            return labeller(inputs[self.views.get(name, GENERALIST_VIEW)](rows))

        return route_rows(choice, len(routes), label, obs.new_empty(obs.shape[0], ACTION_SIZE))

    def _routes(self, code: torch.Tensor, view: torch.Tensor) -> list:
        """(rows, labeller, the name whose view it reads) for every expert given, first match wins; the generalist
        labels the rows no route takes."""
        compensating = code == SCENE_UPSTREAM
        if self.currents is not None:
            current = code == SCENE_CURRENT
            if self.currents == "vertical":  # still water (u = 0) stays with the generalist
                u = view[:, GEO_PRIV_FLOW]
                current = current & (u[:, 2].abs() > u[:, :2].norm(dim=-1))
            compensating = compensating | current
        away, away_name = (self.expert, "expert") if self.away is None else (self.away, "away")
        routes = [
            (code == SCENE_PAPER, self.expert, "expert"),
            (code == SCENE_AWAY, away, away_name),
            (compensating, self.upstream, "upstream"),
        ]
        if self.free is not None:
            routes.append((code == SCENE_FREE, self.free, "free"))
        if self.reverse is not None:
            routes.append((code == SCENE_REVERSE, self.reverse, "reverse"))
        if self.posed is not None:
            routes.append((code == SCENE_POSED, self.posed, "posed"))
        if self.wake_regions is not None:
            routes.append((code == SCENE_WAKE_REGIONS, self.wake_regions, "wake_regions"))
        if self.wake is not None:  # the posed wake's other tasks and the other wakes' regions, unless routed above
            wake = (code == SCENE_WAKE) | (code == SCENE_POSED) | (code == SCENE_WAKE_REGIONS)
            routes.append((wake, self.wake, "wake"))
        return routes


def scene_routed(
    generalist: nn.Module,
    generalist_view: str,
    experts: dict,
    currents: str | None = None,
    free_flows: str | None = None,
) -> SceneRoutedTeacher:
    """The routed teacher of a ``geo_priv`` generalist and its experts: ``experts`` maps the config key
    (``algo.scene_expert``, optionally ``algo.scene_reverse_expert``, ``algo.scene_away_expert``,
    ``algo.scene_wake_expert``, ``algo.scene_posed_expert`` and ``algo.scene_wake_regions_expert``) to (checkpoint
    name, loaded policy, the view its checkpoint records: one of :data:`EXPERT_VIEWS`);
    ``currents``: ``algo.scene_currents``; ``free_flows``: ``algo.scene_free_flows``."""
    if generalist_view != GENERALIST_VIEW:
        raise CheckpointError(
            f"algo.scene_expert routes between a {GENERALIST_VIEW!r} teacher and the paper's; the teacher checkpoint "
            f"reads {generalist_view!r}: pass the generalist teacher (python train.py +experiment=generalist_teacher)"
        )
    box = lambda p: [round(v, 6) for v in p.config["action_low"] + p.config["action_high"]]  # noqa: E731
    for key, (name, policy, view) in experts.items():
        if view not in EXPERT_VIEWS[key]:
            raise CheckpointError(
                f"algo.{key} {name} reads {view!r}; that expert reads one of {list(EXPERT_VIEWS[key])}: pass a "
                "checkpoint trained on one of them"
            )
        if box(policy) != box(generalist):
            raise CheckpointError(f"algo.{key} {name} acts in another action box than the teacher")
    loaded = {key: p for key, (_, p, _) in experts.items()}
    views = {key.removeprefix("scene_").removesuffix("_expert"): view for key, (_, _, view) in experts.items()}
    return SceneRoutedTeacher(
        generalist,
        loaded["scene_expert"],
        u_max=float(generalist.config["action_high"][0]),
        reverse=loaded.get("scene_reverse_expert"),
        away=loaded.get("scene_away_expert"),
        wake=loaded.get("scene_wake_expert"),
        currents=currents,
        posed=loaded.get("scene_posed_expert"),
        free_flows=free_flows,
        wake_regions=loaded.get("scene_wake_regions_expert"),
        views=views,
    )
