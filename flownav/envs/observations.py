"""Observation views computed from one swimmer state.

* ``geo`` (8, eq. 4): target - position and the total velocity in the inertial frame, theta, psi.
* ``ego`` (6, eq. 8): the same two vectors in the body frame (no angles, no inertial frame).
* ``geo_flow`` / ``ego_flow`` (paper SI 1): the local flow velocity instead of the total one.
* ``ego_up`` (8, ours): ``ego`` plus the vertical (inertial z) in the body frame, (sin psi, cos psi).
  The action's turn rates are defined against the vertical (theta turns about it, psi tilts towards
  it), so an ego student that cannot tell up from sideways cannot know which turn the teacher means.
  A gravity sensor measures it on board; it does not change under rotations about z, so the
  misalignment invariance of ``ego`` holds for ``ego_up`` too.
* ``ego_mem`` (8 + 3 K, ours): ``ego_up`` plus a short memory, the local flow velocity of the last K
  samples (every ``HISTORY_STRIDE`` steps), each expressed in the *current* body frame. A memoryless ego
  student sees one noisy flow sample and cannot tell the stream's direction from a vortex's; the flow
  averaged over about one shedding period can. On board: a velocity sensor minus the own swim command
  gives the flow, a gyro turns past samples into the current frame. Rotations about z leave it unchanged.
* ``ego_mem_speed`` (9 + 3 K, ours): ``ego_mem`` plus the swimmer's own full swim speed U (the action's full
  speed times its speed factor): what a robot knows of its own propulsion. Where the families draw weak swimmers
  the same flow calls for another action at another U, and without it an ego student cannot tell which. (The
  generalist recipe with it was no better: docs/generalist_variants.md.)
* ``ego_mem_grad`` (17 + 3 K, ours): ``ego_mem`` plus the flow's gradient in the body frame (9, row-major:
  d u_body_i / d x_body_j), what a lateral-line-like array of flow sensors reads: how the flow changes around the
  swimmer, not only where it is. Forward differences of step ``GRADIENT_STEP`` along the body axes, so the view
  turns with the swimmer: under a rotation of the scene about z it is unchanged, as the other ego views are.
  The generalist student's view (chosen on the validation set: docs/generalist_variants.md).
* ``ego_mem_grad_track`` (17 + 6 K, ours): ``ego_mem_grad`` plus the to-target readings of the same K past samples,
  each in the current body frame: the swimmer's own track against the target. A flow sensor's steady bias reads as a
  current that is not there, and the velocity and the flow memory carry it alike; how the to-target vector changed
  shows where the swimmer really went. On board: the to-target sensor's past readings, turned by the gyro as the
  flow's are. (Students of it trained with a bias held the vertical currents no better than ``ego_mem_grad``'s:
  docs/generalist_variants.md, "The noisy-sensor student trained with a bias too".)
* ``geo_sincos`` (9, ours): ``geo`` with theta as (cos theta, sin theta). theta wraps at +-pi, which is
  heading straight upstream, the very heading of the wake crossing; the angle jumps there and the
  pair does not. Same information as ``geo``. ``geo_flow_sincos``: the same for ``geo_flow`` (SI 1).
* ``privileged`` (14, critics only): ``geo_sincos`` plus the local flow velocity and the flow's phase
  (cos, sin of 2 pi t / period; zeros for a flow without a period). What the simulator knows and the
  swimmer does not: a critic that sees the phase of the periodic wake can tell a vortex arriving from
  one leaving, and gives the actor less noisy advantages. The actor keeps its own view.
* ``geo_priv`` (23, the generalist teacher's actor): ``geo_sincos`` plus the local flow velocity u (3),
  its gradient du_i/dx_j (9, row-major, forward differences of step ``GRADIENT_STEP`` in the env: 3
  more points in the same look-up), the swim speed U (the action's full speed times the swimmer's speed factor) and
  log(U / (|u| + 0.05)), the swim-speed ratio against the local flow. A teacher that knows how the
  flow varies around it and how strong it is against the flow can plan; an ego student imitates it.
* ``geo_priv_wake`` (23): ``geo_priv`` seen from the frame of the swimmer's flow as posed: its vectors, heading
  and gradient turned back by the angle the simulator turned that flow about z (a family member's drawn rotation,
  a flow's ``rotate_deg``, a misaligned scene's angle; 0 otherwise). To a network reading it, a wake turned by any
  angle is the wake as posed, so what it learns at one angle holds at all (the ego views have that invariance by
  turning with the swimmer; the inertial-frame ``geo_priv`` must learn each angle apart). Walls do not turn: no
  view reads them.
* ``geo_priv_around`` (59): ``geo_priv`` plus the flow velocity at 12 points around the swimmer
  (:data:`AROUND_OFFSETS`: 1 and 2 units along +-x, +-y, +-z, inertial frame): what the flow does beyond the
  gradient's reach, for a teacher whose best action depends on where the flow will carry it.
* ``geo_priv_scene`` (25, a scene-routed teacher's view): ``geo_priv``, the angle ``geo_priv_wake`` turns back,
  and 1 where the swimmer is in the
  paper's training task as posed (the unturned CFD wake at strength 1, full swim speed, the target in Region
  2), 2 there when its episode started upstream of the paper's regions, 4 from any other start, 3 from Region 2
  to a target in Region 1, 7 with any other task there (a family slot), 5 in any other full-speed episode in a
  flow of the families with an obstacle (a CFD wake or a vortex street; 9 where that episode is the paper's task,
  Region 1 to Region 2), 6 in their uniform currents and still
  water, 8 in any other full-speed episode of the families (random flows, and those on a current), else 0
  (``flownav.envs.core.paper_scene``): what a teacher needs to hand those episodes to their experts
  (``SceneRoutedTeacher``).
* ``geo_priv_critic`` (27, its asymmetric critic): ``geo_priv`` plus the fraction of the episode's time
  left (what decides truncation, hence the value) and the flow velocity at the target.

Sensor noise (``env.sensor_noise``, off by default) applies to the ego views only, the swimmer's on-board
sensors (``SENSED_VIEWS``), and so does a per-episode bias (``env.sensor_bias``): the geo and privileged views are
what the simulator knows, exactly. ``ego_mem_grad``'s gradient errs only with its own standard deviations
(``env.sensor_noise.gradient``, ``env.sensor_bias.gradient``).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import torch
from torch import Tensor

from flownav.envs.kinematics import body_frame, to_body


@dataclass(frozen=True)
class State:
    """What every view is computed from (all ``[N, ...]``)."""

    to_target: Tensor  # target - position, inertial frame
    velocity: Tensor  # total velocity (swim + flow), inertial frame
    flow: Tensor  # local flow velocity, inertial frame
    theta: Tensor
    psi: Tensor
    frame: Tensor | None  # body frame [N, 3, 3]; None when no ego view is asked for
    flow_history: Tensor | None = None  # [N, HISTORY_LEN, 3] past flow velocities, inertial; memory views only
    target_history: Tensor | None = None  # [N, HISTORY_LEN, 3] the to-target readings of the same steps; track views
    flow_phase: Tensor | None = None  # [N] flow time / period in [0, 1); None: no period (or not asked for)
    flow_gradient: Tensor | None = None  # [N, 3, 3] du_i / dx_j; privileged views only
    body_flow_gradient: Tensor | None = None  # [N, 3, 3] d u_body_i / d x_body_j; ego_mem_grad only
    flow_around: Tensor | None = None  # [N, P, 3] the flow at AROUND_OFFSETS from the swimmer; geo_priv_around
    swim_speed: Tensor | None = None  # [N] the swimmer's full swim speed
    time_left: Tensor | None = None  # [N] fraction of the time limit left; privileged views only
    target_flow: Tensor | None = None  # [N, 3] flow velocity at the target; geo_priv_critic only
    paper_scene: Tensor | None = None  # [N] the paper's scene code (core.paper_scene: 0-9); geo_priv_scene only
    flow_turn: Tensor | None = None  # [N] the angle the swimmer's flow is turned by about z; geo_priv_wake, _scene


# The memory of ``ego_mem``: HISTORY_LEN flow samples, HISTORY_STRIDE steps apart (newest first). With
# dt = 0.2 they span 4.8 time units, about one vortex-shedding period of the Re = 300 wake (St 0.19).
HISTORY_LEN = 7
HISTORY_STRIDE = 4


def _geo(s: State, vel: Tensor) -> Tensor:
    return torch.cat((s.to_target, vel, s.theta[:, None], s.psi[:, None]), -1)


def _ego(s: State, vel: Tensor) -> Tensor:
    return torch.cat((to_body(s.frame, s.to_target), to_body(s.frame, vel)), -1)


def _ego_up(s: State) -> Tensor:
    return torch.cat((_ego(s, s.velocity), torch.sin(s.psi)[:, None], torch.cos(s.psi)[:, None]), -1)


def _ego_mem(s: State) -> Tensor:
    past = to_body(s.frame, s.flow_history).flatten(1)
    return torch.cat((_ego_up(s), past), -1)


def _ego_mem_grad(s: State) -> Tensor:
    return torch.cat((_ego_mem(s), s.body_flow_gradient.flatten(1)), -1)


def _ego_mem_grad_track(s: State) -> Tensor:
    return torch.cat((_ego_mem_grad(s), to_body(s.frame, s.target_history).flatten(1)), -1)


def _ego_mem_speed(s: State) -> Tensor:
    return torch.cat((_ego_mem(s), s.swim_speed[:, None]), -1)


def _geo_sincos(s: State, vel: Tensor) -> Tensor:
    return torch.cat((s.to_target, vel, torch.cos(s.theta)[:, None], torch.sin(s.theta)[:, None], s.psi[:, None]), -1)


def _privileged(s: State) -> Tensor:
    if s.flow_phase is None:  # a flow without a period has no phase
        phase = s.flow.new_zeros(s.flow.shape[0], 2)
    else:
        angle = 2 * math.pi * s.flow_phase[:, None]
        phase = torch.cat((torch.cos(angle), torch.sin(angle)), -1)
    return torch.cat((_geo_sincos(s, s.velocity), s.flow, phase), -1)


# Where geo_priv keeps what it adds to geo_sincos (its first 9 entries).
GEO_PRIV_FLOW, GEO_PRIV_SWIM_SPEED = slice(9, 12), slice(21, 22)


def _geo_priv(s: State) -> Tensor:
    ratio = torch.log(s.swim_speed / (s.flow.norm(dim=-1) + 0.05))
    extra = (s.flow, s.flow_gradient.flatten(1), s.swim_speed[:, None], ratio[:, None])
    return torch.cat((_geo_sincos(s, s.velocity), *extra), -1)


# The probe points of geo_priv_around, relative to the swimmer: +-x, +-y, +-z at 1 and 2 units.
AROUND_OFFSETS = tuple(
    tuple(sign * radius * (axis == a) for a in range(3))
    for radius in (1.0, 2.0)
    for axis in range(3)
    for sign in (1, -1)
)


def _geo_priv_around(s: State) -> Tensor:
    return torch.cat((_geo_priv(s), s.flow_around.flatten(1)), -1)


def turn_geo_priv(obs: Tensor, angle: Tensor) -> Tensor:
    """Rows that begin with ``geo_priv``'s 23 numbers as seen from a frame turned by ``angle`` [N] about z: the
    to-target vector, velocity, heading (cos, sin) and flow in that frame (R^T v), the gradient G as R^T G R; the
    rest as is."""
    frame = body_frame(angle, torch.zeros_like(angle))  # a level frame turned by angle: R
    out = obs.clone()
    for i in (0, 3, 9):  # to_target, velocity, flow
        out[:, i : i + 3] = to_body(frame, obs[:, i : i + 3])
    heading = torch.cat((obs[:, 6:8], torch.zeros_like(obs[:, :1])), -1)  # (cos theta, sin theta, 0)
    out[:, 6:8] = to_body(frame, heading)[:, :2]
    grad = obs[:, 12:21].reshape(-1, 3, 3)  # G[i, j] = du_i / dx_j
    out[:, 12:21] = (frame.transpose(1, 2) @ grad @ frame).reshape(-1, 9)
    return out


def _geo_priv_wake(s: State) -> Tensor:
    return turn_geo_priv(_geo_priv(s), s.flow_turn)


def _geo_priv_scene(s: State) -> Tensor:
    return torch.cat((_geo_priv(s), s.flow_turn[:, None], s.paper_scene[:, None]), -1)


def _geo_priv_critic(s: State) -> Tensor:
    return torch.cat((_geo_priv(s), s.time_left[:, None], s.target_flow), -1)


VIEWS: dict[str, tuple[int, Callable[[State], Tensor]]] = {
    "geo": (8, lambda s: _geo(s, s.velocity)),
    "ego": (6, lambda s: _ego(s, s.velocity)),
    "geo_flow": (8, lambda s: _geo(s, s.flow)),
    "ego_flow": (6, lambda s: _ego(s, s.flow)),
    "ego_up": (8, _ego_up),
    "ego_mem": (8 + 3 * HISTORY_LEN, _ego_mem),
    "ego_mem_speed": (9 + 3 * HISTORY_LEN, _ego_mem_speed),
    "ego_mem_grad": (17 + 3 * HISTORY_LEN, _ego_mem_grad),
    "ego_mem_grad_track": (17 + 6 * HISTORY_LEN, _ego_mem_grad_track),
    "geo_sincos": (9, lambda s: _geo_sincos(s, s.velocity)),
    "geo_flow_sincos": (9, lambda s: _geo_sincos(s, s.flow)),
    "privileged": (14, _privileged),
    "geo_priv": (23, _geo_priv),
    "geo_priv_critic": (27, _geo_priv_critic),
    "geo_priv_scene": (25, _geo_priv_scene),
    "geo_priv_wake": (23, _geo_priv_wake),
    "geo_priv_around": (23 + 3 * len(AROUND_OFFSETS), _geo_priv_around),
}
MEMORY_VIEWS = ("ego_mem", "ego_mem_speed", "ego_mem_grad", "ego_mem_grad_track")
TRACK_VIEWS = ("ego_mem_grad_track",)  # a memory of the to-target readings as well
SENSED_VIEWS = tuple(name for name in VIEWS if name.startswith("ego"))  # on-board sensors: env.sensor_noise
PHASE_VIEWS = ("privileged",)
# The views that read the flow's gradient (the env computes it for them) and the time left.
GRADIENT_VIEWS = ("geo_priv", "geo_priv_critic", "geo_priv_scene", "geo_priv_around", "geo_priv_wake")
# The gradient along the body axes (the env computes it for them).
BODY_GRADIENT_VIEWS = ("ego_mem_grad", "ego_mem_grad_track")
SWIM_SPEED_VIEWS = (*GRADIENT_VIEWS, "ego_mem_speed")  # the swimmer's own full swim speed
TARGET_FLOW_VIEWS = ("geo_priv_critic",)
SCENE_VIEWS = ("geo_priv_scene",)
TURN_VIEWS = ("geo_priv_scene", "geo_priv_wake")  # the angle the swimmer's flow is turned by
AROUND_VIEWS = ("geo_priv_around",)
GEO_VIEWS = tuple(name for name in VIEWS if name.startswith("geo"))  # the teacher's kind: inertial frame


def needs_body_frame(names) -> bool:
    return any(name.startswith("ego") for name in names)


def needs_history(names) -> bool:
    return any(name in MEMORY_VIEWS for name in names)


def needs_track(names) -> bool:
    return any(name in TRACK_VIEWS for name in names)


def needs_phase(names) -> bool:
    return any(name in PHASE_VIEWS for name in names)


def needs_gradient(names) -> bool:
    return any(name in GRADIENT_VIEWS for name in names)


def needs_body_gradient(names) -> bool:
    return any(name in BODY_GRADIENT_VIEWS for name in names)


def needs_swim_speed(names) -> bool:
    return any(name in SWIM_SPEED_VIEWS for name in names)


def needs_target_flow(names) -> bool:
    return any(name in TARGET_FLOW_VIEWS for name in names)


def needs_around(names) -> bool:
    return any(name in AROUND_VIEWS for name in names)


def needs_scene(names) -> bool:
    return any(name in SCENE_VIEWS for name in names)


def needs_turn(names) -> bool:
    return any(name in TURN_VIEWS for name in names)


def check_views(names) -> tuple[str, ...]:
    names = tuple(names)
    unknown = [n for n in names if n not in VIEWS]
    if unknown or not names:
        raise ValueError(f"unknown observation view(s) {unknown or names}; choose from {sorted(VIEWS)}")
    return names


def observation_size(name: str) -> int:
    return VIEWS[check_views([name])[0]][0]


def compute_views(state: State, names) -> dict[str, Tensor]:
    return {name: VIEWS[name][1](state) for name in names}
