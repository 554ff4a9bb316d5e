"""The physics of navigation as plain torch functions of a batch of swimmers.

    state = initial_state(num_envs, settings, device)
    state = reset(state, idx, flow, settings, rng)     # new episodes in the slots idx
    state, reward = step(state, action, flow, settings)  # state.status says how each episode stands
    views = observe(state, flow, settings)              # {view name: [B, size]}
    ended = (state.status != Status.RUNNING).nonzero().squeeze(-1)   # then reset(state, ended, ...)

A step turns the heading, moves every swimmer with swim + flow velocity (eq. 1-3), then looks the flow
up once at the new positions: that value is both the flow the next step moves with and the flow the
observations report, so each step costs exactly one flow look-up (plus the privileged views' probes).
Episode time is the step count times dt, so the time limit is a whole number of steps.

``flow`` is the scene's flow as :func:`scene_flow` prepares it (rotated for a misaligned wake, one flow
per slot for a flow family); a family's slots are redrawn by :func:`reset` and live in the flow object.
:class:`~flownav.envs.navigation.NavigationEnv` is the TorchRL adapter of these functions.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields, replace
from enum import IntEnum
from typing import NamedTuple

import torch
from torch import Tensor

from flownav.envs.kinematics import (
    body_frame,
    from_body,
    heading_vector,
    move,
    step_reaches,
    to_body,
    turn,
    wrap_angle,
)
from flownav.envs.observations import (
    AROUND_OFFSETS,
    HISTORY_LEN,
    HISTORY_STRIDE,
    SENSED_VIEWS,
    State,
    compute_views,
    needs_around,
    needs_body_frame,
    needs_body_gradient,
    needs_gradient,
    needs_history,
    needs_phase,
    needs_scene,
    needs_swim_speed,
    needs_target_flow,
    needs_track,
    needs_turn,
)
from flownav.envs.reward import RewardConfig, step_reward
from flownav.envs.tasks import REGION_1, REGION_2
from flownav.errors import ConfigError, require_finite
from flownav.flows.base import FlowField
from flownav.flows.families import FlowFamily
from flownav.flows.grid import GridFlow
from flownav.flows.transforms import RotatedFlow, rotate_z

# Action bounds of the paper (section 2.3.2): U in [0, U_max], dtheta, dpsi in rad per time unit.
DTHETA_MAX = math.pi / 4
DPSI_MAX = math.pi / 2
FLOW_FIX = "the flow must be finite over the whole domain (a FunctionFlow's function, a dataset's frames)"
# Forward-difference step of the flow gradient the views read (below the wake grid's spacing 0.25).
GRADIENT_STEP = 0.05


class Status(IntEnum):
    RUNNING = 0
    SUCCESS = 1
    LEFT_DOMAIN = 2
    HIT_OBSTACLE = 3
    TIMEOUT = 4


@dataclass(frozen=True)
class Settings:
    """Everything besides the flow and the state that episodes and steps depend on (NavigationEnv's arguments).

    task: ``sample(n, generator, device) -> (start, target)``, optionally ``swim_speed(n, generator, device)``
    (each episode's factor on ``swim_speed_scale``). views: the observation views (they decide what is sensed).
    max_steps: the time limit in steps. misalignment_deg: the scene turned about z through ``rotation_center``.
    flow_strength: ``(low, high)`` of each episode's factor on the flow, or None; flow_strength_full: the share
    of episodes at 1. sensor_noise: ``(flow, target, gradient)`` standard deviations of the ego views' sensors'
    errors drawn fresh each step, sensor_bias: of their errors drawn once per episode (:func:`draw_sensor_error`),
    sensor_bias_frame: where the flow's and to-target's bias is fixed, "world" or "body" (:func:`reading_error`).
    """

    task: object
    views: tuple[str, ...]
    dt: float
    max_steps: int
    u_max: float
    swim_speed_scale: float
    reward: RewardConfig
    misalignment_deg: float = 0.0
    rotation_center: tuple[float, float] = (0.0, 0.0)
    random_flow_phase: bool = True
    flow_strength: tuple[float, float] | None = None
    flow_strength_full: float = 0.0
    sensor_noise: tuple[float, float, float] = (0.0, 0.0, 0.0)
    sensor_bias: tuple[float, float, float] = (0.0, 0.0, 0.0)
    sensor_bias_frame: str = "world"

    def _read_with_error(self, sd: tuple[float, float, float]) -> bool:
        """Whether a view reads a sensor to which ``(flow, target, gradient)`` standard deviations give an error: an
        error no view reads draws nothing, so the random streams stay as they were without it."""
        ego = any(v in SENSED_VIEWS for v in self.views)
        return (ego and any(sd[:2])) or (sd[2] > 0 and needs_body_gradient(self.views))

    @property
    def gradient_noisy(self) -> bool:
        """Whether a view reads the body-axis gradient and it errs (fresh each step or per episode)."""
        return self._read_with_error((0.0, 0.0, self.sensor_noise[2] + self.sensor_bias[2]))

    @property
    def noisy(self) -> bool:
        """Whether the ego views read erring sensors (fresh errors, a per-episode bias or both)."""
        return self._read_with_error(self.sensor_noise) or self.biased

    @property
    def biased(self) -> bool:
        """Whether a sensor that a view reads errs by a per-episode bias as well (drawn at reset)."""
        return self._read_with_error(self.sensor_bias)

    @property
    def body_bias(self) -> bool:
        """Whether the flow's and to-target's bias turns with the swimmer (fixed in its body frame)."""
        return self.biased and self.sensor_bias_frame == "body"

    @property
    def sensor_error_width(self) -> int:
        """Standard-normal errors per reading: flow (3) and to-target (3), plus the gradient's (9) when it errs and a
        view reads it (so an env whose views read no gradient draws what it would without the gradient's noise)."""
        return 6 + 9 * self.gradient_noisy


@dataclass
class Swimmers:
    """The batch's state, one row per slot: everything a step reads, and what an exact resume saves.

    ``flow_ring`` (memory views; ``[B, 0, 3]`` without) and ``target_ring`` (track views) are written in place, so
    that a step's cost does not grow with their length: a state handed to :func:`step` or :func:`reset` shares its
    rings with the result.
    """

    pos: Tensor  # [B, 3]
    start: Tensor  # [B, 3] where the episode started
    target: Tensor  # [B, 3]
    vel: Tensor  # [B, 3] total velocity (swim + flow)
    flow_vel: Tensor  # [B, 3] the flow at pos, now: the next step moves with it, the views report it
    theta: Tensor  # [B] heading in the x-y plane
    psi: Tensor  # [B] elevation
    time: Tensor  # [B] steps * dt
    t0: Tensor  # [B] the episode's start time in the flow
    strength: Tensor  # [B] the episode's factor on the flow (read only with settings.flow_strength)
    start_dist: Tensor  # [B]
    dist: Tensor  # [B] distance to the target
    speed: Tensor  # [B] the swim speed of the last step
    status: Tensor  # [B] int64, a Status
    steps: Tensor  # [B] int64, steps into the episode
    flow_ring: Tensor  # [B, R, 3] the last R flow samples; all slots step together, so one pointer serves all
    target_ring: Tensor  # [B, R, 3] the to-target readings of the same steps (track views; [B, 0, 3] without)
    ring_ptr: int
    swim_scale: Tensor  # [B] the factor on the action's speed (settings.swim_speed_scale times the task's draw)
    flow_grad: Tensor  # [B, 3, 3] du_i / dx_j (privileged views)
    body_flow_grad: Tensor  # [B, 3, 3] d u_body_i / d x_body_j, differences along the body axes (ego_mem_grad)
    target_flow: Tensor  # [B, 3] the flow at the target (privileged critic)
    flow_around: Tensor  # [B, P, 3] the flow at AROUND_OFFSETS from the swimmer (geo_priv_around)
    scene: Tensor  # [B] int64 the episode's paper-scene code (:func:`paper_scene`; the scene view), set at reset
    sensor_error: Tensor  # [B, 6 or 15] standard-normal errors of the last reading: flow (3), to-target (3),
    # body-axis gradient (9, with a gradient error; Settings.sensor_error_width); zeros if exact
    sensor_bias: Tensor  # [B, 6 or 15] the same, drawn once per episode (Settings.sensor_bias); zeros without


STATE_FIELDS = tuple(f.name for f in fields(Swimmers))
# What an exact resume saves: all but the scene, which follows from the episode and its flow (keep_scene).
SAVED_FIELDS = tuple(name for name in STATE_FIELDS if name != "scene")


class Episodes(NamedTuple):
    """New episodes' draws, in the (possibly rotated) scene; strength None without settings.flow_strength."""

    start: Tensor
    target: Tensor
    theta: Tensor
    psi: Tensor
    t0: Tensor
    strength: Tensor | None


def scene_flow(flow: FlowField, settings: Settings, num_envs: int, device) -> FlowField:
    """The flow the swimmers meet: on ``device``, turned by the misalignment, a family with one slot per swimmer."""
    flow = flow.to(device)
    if isinstance(flow, FlowFamily):
        if settings.misalignment_deg:
            raise ValueError("misalignment_deg rotates one flow; a flow family draws its own rotations (angle_deg)")
        return flow.bind(num_envs, device)
    if settings.misalignment_deg:
        return RotatedFlow(flow, settings.misalignment_deg, settings.rotation_center)
    return flow


def initial_state(num_envs: int, settings: Settings, device) -> Swimmers:
    """Every slot zero (call :func:`reset` before stepping)."""
    z = lambda *s: torch.zeros(num_envs, *s, device=device)  # noqa: E731
    ring = (HISTORY_LEN - 1) * HISTORY_STRIDE + 1 if needs_history(settings.views) else 0
    return Swimmers(
        pos=z(3),
        start=z(3),
        target=z(3),
        vel=z(3),
        flow_vel=z(3),
        theta=z(),
        psi=z(),
        time=z(),
        t0=z(),
        strength=torch.ones(num_envs, device=device),
        start_dist=z(),
        dist=z(),
        speed=z(),
        status=torch.zeros(num_envs, dtype=torch.int64, device=device),
        steps=torch.zeros(num_envs, dtype=torch.int64, device=device),
        flow_ring=z(ring, 3),
        target_ring=z(ring if needs_track(settings.views) else 0, 3),
        ring_ptr=0,
        swim_scale=torch.full((num_envs,), settings.swim_speed_scale, device=device),
        flow_grad=z(3, 3),
        body_flow_grad=z(3, 3),
        target_flow=z(3),
        flow_around=z(len(AROUND_OFFSETS), 3),
        scene=torch.zeros(num_envs, dtype=torch.int64, device=device),
        sensor_error=z(settings.sensor_error_width),
        sensor_bias=z(settings.sensor_error_width),
    )


def action_bounds(settings: Settings, device) -> tuple[Tensor, Tensor]:
    """(low, high) of an action (U, dtheta, dpsi), ``[3]`` each."""
    low = torch.tensor([0.0, -DTHETA_MAX, -DPSI_MAX], device=device)
    high = torch.tensor([settings.u_max, DTHETA_MAX, DPSI_MAX], device=device)
    return low, high


def flow_at(flow: FlowField, settings: Settings, strength: Tensor, pos: Tensor, t: Tensor, idx=None) -> Tensor:
    """The flow velocity the swimmers feel (all slots, or the slots ``idx``): the flow's, times the episode's
    ``strength`` (a ``[B]`` tensor, the state's) when ``settings.flow_strength`` is set."""
    u = flow.velocity(pos, t, idx) if isinstance(flow, FlowFamily) else flow.velocity(pos, t)
    if settings.flow_strength is None:
        return u
    s = strength if idx is None else strength[idx]
    return u * s[:, None]


def flow_of_rows(flow: FlowField, idx: Tensor) -> FlowField:
    """The flow of a batch whose row i belongs to slot ``idx[i]``, for many look-ups of the same rows (flow_at and
    in_obstacle with idx=None): a family taken for them (each slot's parameters gathered once), any other as it is."""
    return flow.take(idx) if isinstance(flow, FlowFamily) else flow


def in_obstacle(flow: FlowField, pos: Tensor, idx: Tensor | None = None) -> Tensor:
    """Rows of ``pos`` inside an obstacle; a family needs the env slot of each row (``idx``)."""
    return flow.in_obstacle(pos, idx) if isinstance(flow, FlowFamily) else flow.in_obstacle(pos)


def sample_episodes(n: int, flow: FlowField, settings: Settings, rng: torch.Generator, idx=None) -> Episodes:
    """Starts, targets, headings, flow start times and strengths of n new episodes (for the slots ``idx`` of a
    family flow), drawn from ``rng`` in a fixed order: the task (rejected episodes drawn again), theta, psi, t0
    (random_flow_phase with a periodic flow), the strength."""
    device = rng.device
    base = flow.base if isinstance(flow, RotatedFlow) else flow
    family = isinstance(flow, FlowFamily)
    # A family task may treat the slots whose flow is the wake as posed apart (FamilyTask.reads_posed).
    posed = {"posed": flow.wake_as_posed(idx)} if family and getattr(settings.task, "reads_posed", False) else {}
    start, target = settings.task.sample(n, rng, device, **posed)
    start, target = start.to(device, torch.float32), target.to(device, torch.float32)
    # Rejection in the unrotated scene: a start must lie in the domain, outside obstacles and the success ball.
    for _ in range(100):
        bad = (
            ~base.in_domain(start)
            | in_obstacle(base, start, idx)
            | (base.displacement(start, target).norm(dim=-1) <= settings.reward.success_radius)
        )
        if not bad.any():
            break
        # a rejected episode is drawn again whole, from its slot's own distribution (a family's posed wake too)
        fresh, fresh_target = settings.task.sample(n, rng, device, **posed)
        start = torch.where(bad[:, None], fresh.to(start), start)
        target = torch.where(bad[:, None], fresh_target.to(target), target)
    else:
        raise ConfigError(
            "task= does not fit flow=: after 100 draws some of the task's starts still lie outside the flow's domain, "
            "inside an obstacle or within env.reward.success_radius of their target; pick a task made for this flow "
            "(e.g. flow=abc with task=abc, as +experiment=teacher_abc does)"
        )
    theta = (torch.rand(n, generator=rng, device=device) * 2 - 1) * math.pi
    psi = torch.asin(torch.rand(n, generator=rng, device=device) * 2 - 1)  # uniform on the sphere
    if settings.misalignment_deg:
        angle = math.radians(settings.misalignment_deg)
        start = rotate_z(start, angle, settings.rotation_center)
        target = rotate_z(target, angle, settings.rotation_center)
        theta = theta + angle
    if settings.random_flow_phase and flow.period:
        t0 = torch.rand(n, generator=rng, device=device) * flow.period
    else:
        t0 = torch.zeros(n, device=device)
    strength = None
    if settings.flow_strength is not None:  # drawn last: the other draws are those of settings without it
        low, high = settings.flow_strength
        strength = low + (high - low) * torch.rand(n, generator=rng, device=device)
        if settings.flow_strength_full:
            full = torch.rand(n, generator=rng, device=device) < settings.flow_strength_full
            strength = torch.where(full, torch.ones_like(strength), strength)
    return Episodes(start, target, wrap_angle(theta), psi, t0, strength)


def reset(state: Swimmers, idx: Tensor, flow: FlowField, settings: Settings, rng: torch.Generator) -> Swimmers:
    """New episodes in the slots ``idx``; the other slots keep their state. Draws from ``rng``: a family's new
    flows, then :func:`sample_episodes`, then the task's swim speeds."""
    if not idx.numel():
        return state
    if isinstance(flow, FlowFamily):
        flow.resample(idx, rng)
    ep = sample_episodes(idx.numel(), flow, settings, rng, idx)
    # Out of place: tensors handed out earlier (observations) keep their values.
    put = lambda old, new: old.index_put((idx,), new)  # noqa: E731
    strength, swim_scale = state.strength, state.swim_scale
    if ep.strength is not None:
        strength = put(strength, ep.strength)
    if hasattr(settings.task, "swim_speed"):  # drawn last: tasks without it keep their random streams
        swim_scale = put(swim_scale, settings.swim_speed_scale * settings.task.swim_speed(idx.numel(), rng, rng.device))
    flow_vel, privileged = sense_flow(flow, settings, strength, ep.start, ep.t0, ep.target, ep.theta, ep.psi, idx)
    require_finite(flow_vel, "the flow velocity at the start", FLOW_FIX, ep.start)
    to_target = flow.displacement(ep.start, ep.target)
    d = to_target.norm(dim=-1)
    zero, zero_int = torch.zeros_like(d), torch.zeros_like(idx)
    error, bias = state.sensor_error, state.sensor_bias
    if settings.noisy:  # drawn last: exact sensors keep the random streams of the other draws
        error = put(error, draw_sensor_error(idx.numel(), rng, settings.sensor_error_width))
    if settings.biased:  # after the fresh errors: sensors without a bias keep their streams
        bias = put(bias, draw_sensor_error(idx.numel(), rng, settings.sensor_error_width))
    if state.flow_ring.shape[1]:  # no past yet: the swimmer has been sensing its start flow (and target)
        frame = bias_frame(settings, ep.theta, ep.psi)
        state.flow_ring[idx] = sensed_flow(flow_vel, error[idx], bias[idx], settings, frame)[:, None, :]
        if state.target_ring.shape[1]:  # a track view is a memory view: its ring steps with the flow's
            state.target_ring[idx] = sensed_to_target(to_target, error[idx], bias[idx], settings, frame)[:, None, :]
    state = replace(
        state,
        pos=put(state.pos, ep.start),
        start=put(state.start, ep.start),
        target=put(state.target, ep.target),
        theta=put(state.theta, ep.theta),
        psi=put(state.psi, ep.psi),
        t0=put(state.t0, ep.t0),
        time=put(state.time, zero),
        speed=put(state.speed, zero),
        status=put(state.status, zero_int),
        steps=put(state.steps, zero_int),
        flow_vel=put(state.flow_vel, flow_vel),
        vel=put(state.vel, flow_vel),  # at rest relative to the fluid until the first action
        start_dist=put(state.start_dist, d),
        dist=put(state.dist, d),
        strength=strength,
        swim_scale=swim_scale,
        sensor_error=error,
        sensor_bias=bias,
        **{key: getattr(state, key).index_put((idx,), value) for key, value in privileged.items()},
    )
    return keep_scene(state, flow, settings, idx)


def draw_sensor_error(n: int, rng: torch.Generator, width: int) -> Tensor:
    """Standard-normal errors of n readings, ``[n, width]``: the flow sensor's (3), the to-target sensor's (3) and,
    with ``width`` 15, the gradient sensor's (9). The ego views read the flow as u + sigma_flow e (the total velocity
    as the exactly known swim velocity plus that reading; the memory keeps the readings as sensed), the to-target
    vector d as d + sigma_target |d| e (a relative range and bearing error) and each component of the body-axis
    gradient as G_ij + sigma_gradient e_ij; one fresh draw per step (:func:`sensed_state`), and with a bias one
    more per episode, b, added as sigma_bias b (:func:`reading_error`). The gradient's errors are drawn after the
    others: without them a draw is what it was before the gradient could err."""
    error = torch.randn(n, 6, generator=rng, device=rng.device)
    if width == 6:
        return error
    return torch.cat((error, torch.randn(n, width - 6, generator=rng, device=rng.device)), -1)


FLOW_SENSOR, TARGET_SENSOR, GRADIENT_SENSOR = 0, 1, 2
SENSOR_COLUMNS = (slice(0, 3), slice(3, 6), slice(6, 15))  # of draw_sensor_error's draws


def reading_error(
    sensor: int,
    error: Tensor,
    bias: Tensor,
    settings: Settings,
    scale: Tensor | float = 1.0,
    frame: Tensor | None = None,
) -> Tensor:
    """A sensor's error in the frame of its reading from its standard-normal draws: (sigma_noise scale) e +
    (sigma_bias scale) b, ``scale`` the reading's length for the relative to-target error (no bias term without a
    bias: exact as before it existed). With ``settings.body_bias`` the flow's and to-target's b are body-frame
    components, turned into the world frame by ``frame`` (:func:`~flownav.envs.kinematics.body_frame` of the
    swimmer's heading when it reads); the gradient's b is per body-axis component either way."""
    cols = SENSOR_COLUMNS[sensor]
    out = settings.sensor_noise[sensor] * scale * error[:, cols]
    if not settings.biased:
        return out
    b = bias[:, cols]
    if settings.body_bias and sensor != GRADIENT_SENSOR:
        b = from_body(frame, b)
    return out + settings.sensor_bias[sensor] * scale * b


def bias_frame(settings: Settings, theta: Tensor, psi: Tensor) -> Tensor | None:
    """The body frame at the heading ``(theta, psi)`` when a bias turns with the swimmer, else None (nothing to
    compute: only that bias reads the heading, :func:`reading_error`)."""
    return body_frame(theta, psi) if settings.body_bias else None


def sensed_flow(flow_vel: Tensor, error: Tensor, bias: Tensor, settings: Settings, frame: Tensor | None) -> Tensor:
    """The flow as the ego views' sensor reads it (exact without sensor errors; ``frame``: :func:`bias_frame`)."""
    if not settings.noisy:
        return flow_vel
    return flow_vel + reading_error(FLOW_SENSOR, error, bias, settings, frame=frame)


def sensed_to_target(
    to_target: Tensor, error: Tensor, bias: Tensor, settings: Settings, frame: Tensor | None
) -> Tensor:
    """The to-target vector as the ego views' sensor reads it, its error relative to its length (as
    :func:`sensed_flow`)."""
    if not settings.noisy:
        return to_target
    return to_target + reading_error(TARGET_SENSOR, error, bias, settings, to_target.norm(dim=-1, keepdim=True), frame)


def keep_scene(state: Swimmers, flow: FlowField, settings: Settings, idx: Tensor) -> Swimmers:
    """The state with the paper-scene code of the episodes in the slots ``idx`` (when a view reads it): it depends
    only on what a reset draws, so it is computed once per episode, not at every step."""
    if not needs_scene(settings.views):
        return state
    return replace(state, scene=state.scene.index_put((idx,), paper_scene(state, flow, settings, idx)))


def step(
    state: Swimmers, action: Tensor, flow: FlowField, settings: Settings, rng: torch.Generator | None = None
) -> tuple[Swimmers, Tensor]:
    """One step of every slot with ``action`` ``[B, 3]`` (clipped to :func:`action_bounds`): the new state
    (its ``status`` says which episodes ended and why) and the reward ``[B]`` of eq. 6. Ended episodes stay
    as they ended until :func:`reset`. ``rng``: the env's generator, which noisy sensors draw from."""
    require_finite(action, "the action", "the policy produced it: check its weights and observations")
    low, high = action_bounds(settings, action.device)
    speed, dtheta, dpsi = torch.max(torch.min(action, high), low).unbind(-1)
    theta, psi = turn(state.theta, state.psi, dtheta, dpsi, settings.dt)
    speed = speed * state.swim_scale
    swim = speed[:, None] * heading_vector(theta, psi)
    moved, _ = move(state.pos, swim, state.flow_vel, settings.dt)
    pos = flow.wrap(moved)  # periodic axes: back into the box
    steps = state.steps + 1
    time = steps * settings.dt
    flow_vel, privileged = sense_flow(flow, settings, state.strength, pos, state.t0 + time, state.target, theta, psi)
    require_finite(flow_vel, "the flow velocity", FLOW_FIX, pos)
    error = state.sensor_error
    if settings.noisy:
        if rng is None:
            raise ValueError("sensor noise draws from the env's generator: pass rng to step")
        error = draw_sensor_error(pos.shape[0], rng, settings.sensor_error_width)
    to_target = flow.displacement(pos, state.target)
    ring_ptr = state.ring_ptr
    if state.flow_ring.shape[1]:
        ring_ptr = (ring_ptr + 1) % state.flow_ring.shape[1]
        frame = bias_frame(settings, theta, psi)
        state.flow_ring[:, ring_ptr] = sensed_flow(flow_vel, error, state.sensor_bias, settings, frame)
        if state.target_ring.shape[1]:
            state.target_ring[:, ring_ptr] = sensed_to_target(to_target, error, state.sensor_bias, settings, frame)

    radius = settings.reward.success_radius
    dist = to_target.norm(dim=-1)
    # Along the whole step, not only at its end: a fast step must not jump over the success ball.
    success = step_reaches(flow.displacement(state.pos, state.target), moved - state.pos, radius)
    left = ~flow.in_domain(pos)
    hit = flow.in_obstacle(pos)
    status = torch.full_like(state.status, Status.RUNNING)
    status = torch.where(steps >= settings.max_steps, Status.TIMEOUT, status)
    status = torch.where(hit, Status.HIT_OBSTACLE, status)
    status = torch.where(left, Status.LEFT_DOMAIN, status)
    status = torch.where(success, Status.SUCCESS, status)
    reward = step_reward(settings.reward, state.dist, dist, state.start_dist, success, settings.dt)
    require_finite(reward, "the reward", "check env.reward (alpha, success_bonus, time_penalty, ...)")
    state = replace(
        state,
        pos=pos,
        theta=theta,
        psi=psi,
        speed=speed,
        steps=steps,
        time=time,
        flow_vel=flow_vel,
        vel=swim + flow_vel,
        ring_ptr=ring_ptr,
        dist=dist,
        status=status,
        sensor_error=error,
        **privileged,
    )
    return state, reward


def sense_flow(
    flow: FlowField,
    settings: Settings,
    strength: Tensor,
    pos: Tensor,
    t: Tensor,
    target: Tensor,
    theta: Tensor,
    psi: Tensor,
    idx=None,
) -> tuple[Tensor, dict[str, Tensor]]:
    """The flow velocity the swimmers feel at ``pos`` (all slots, or the slots ``idx``) and what the views ask for
    beyond it: for the privileged views, what only the simulator knows: the flow's gradient by forward differences
    along the inertial axes (``flow_grad``), the flow at ``target`` (``target_flow``) and at :data:`AROUND_OFFSETS`
    from ``pos`` (``flow_around``); for ``ego_mem_grad`` the gradient by forward differences along the body axes of
    heading ``theta``, ``psi``, in body components (``body_flow_grad``); ``{}`` when no view asks. One look-up of
    1 to 20 points per swimmer: a family's per-call cost is paid once."""
    views = settings.views
    inertial, body = needs_gradient(views), needs_body_gradient(views)
    if not (inertial or body):
        return flow_at(flow, settings, strength, pos, t, idx), {}
    target_flow, around = inertial and needs_target_flow(views), inertial and needs_around(views)
    n = pos.shape[0]
    slots = torch.arange(n, device=pos.device) if idx is None else idx
    parts = [pos[None]]
    if inertial:
        parts.append(pos[None] + torch.eye(3, device=pos.device)[:, None] * GRADIENT_STEP)  # [3 (j), n, 3]: + h e_j
    if target_flow:
        parts.append(target[None])
    if around:
        parts.append(pos[None] + pos.new_tensor(AROUND_OFFSETS)[:, None])  # [P, n, 3]
    if body:
        frame = body_frame(theta, psi)  # columns: the body axes
        parts.append(pos[None] + frame.permute(2, 0, 1) * GRADIENT_STEP)  # [3 (j), n, 3]: + h b_j
    points = torch.cat(parts)
    rows = points.shape[0]
    u = flow_at(flow, settings, strength, points.reshape(-1, 3), t.repeat(rows), slots.repeat(rows)).view(rows, n, 3)
    # [n, j (the step's direction), i (inertial component)]: the forward differences of the three rows from ``row``
    differences = lambda row: ((u[row : row + 3] - u[0]) / GRADIENT_STEP).transpose(0, 1)  # noqa: E731
    out, row = {}, 1
    if inertial:
        out["flow_grad"] = differences(1).transpose(1, 2)  # [n, i (component), j (d/dx_j)]
        row = 4
    if target_flow:
        out["target_flow"], row = u[row], row + 1
    if around:
        out["flow_around"] = u[row : row + len(AROUND_OFFSETS)].transpose(0, 1)  # [n, P, 3]
        row += len(AROUND_OFFSETS)
    if body:
        out["body_flow_grad"] = to_body(frame, differences(row)).transpose(1, 2)  # [n, i (body component), j]
    return u[0], out


def observe(state: Swimmers, flow: FlowField, settings: Settings) -> dict[str, Tensor]:
    """The observation views of ``settings.views``, ``{name: [B, size]}`` (flownav.envs.observations)."""
    views = settings.views
    privileged = {}
    if needs_gradient(views):
        privileged = {
            "flow_gradient": state.flow_grad,
            "target_flow": state.target_flow,
            "flow_around": state.flow_around,
            "time_left": 1 - state.steps / settings.max_steps,
        }
    if needs_body_gradient(views):
        privileged["body_flow_gradient"] = state.body_flow_grad
    if needs_scene(views):
        privileged["paper_scene"] = state.scene.to(state.pos.dtype)
    if needs_turn(views):
        privileged["flow_turn"] = flow_turn(flow, state.pos)
    seen = State(
        to_target=flow.displacement(state.pos, state.target),
        velocity=state.vel,
        flow=state.flow_vel,
        theta=state.theta,
        psi=state.psi,
        frame=body_frame(state.theta, state.psi) if needs_body_frame(views) else None,  # skipped for geo-only
        flow_history=ring_history(state.flow_ring, state.ring_ptr) if needs_history(views) else None,
        target_history=ring_history(state.target_ring, state.ring_ptr) if needs_track(views) else None,
        flow_phase=flow_phase(state, flow) if needs_phase(views) else None,
        swim_speed=settings.u_max * state.swim_scale if needs_swim_speed(views) else None,
        **privileged,
    )
    if not settings.noisy:
        return compute_views(seen, views)
    sensed = [v for v in views if v in SENSED_VIEWS]
    exact = compute_views(seen, [v for v in views if v not in SENSED_VIEWS])
    return exact | compute_views(sensed_state(seen, state, settings), sensed)


def flow_turn(flow: FlowField, pos: Tensor) -> Tensor:
    """The angle (radians, about z) each slot's flow is turned by from its base flow as posed: a family member's
    drawn rotation, else the sum of the rotations the flow is wrapped in (``flow.rotate_deg``, a misaligned scene)."""
    if isinstance(flow, FlowFamily):
        return flow.turn(torch.arange(pos.shape[0], device=pos.device)).to(pos.dtype)
    angle = 0.0
    while flow is not None:
        angle += flow.angle if isinstance(flow, RotatedFlow) else 0.0
        flow = getattr(flow, "base", None)
    return pos.new_full((pos.shape[0],), angle)


def sensed_state(seen: State, state: Swimmers, settings: Settings) -> State:
    """What the ego views read with erring sensors (:func:`reading_error`): the flow reading with its error,
    the total velocity as the swim velocity plus that reading, the to-target vector with its relative error, the
    body-axis gradient with its error (the memory already holds the readings as sensed)."""
    error, bias = state.sensor_error, state.sensor_bias
    flow_error = reading_error(FLOW_SENSOR, error, bias, settings, frame=seen.frame)
    to_target = sensed_to_target(seen.to_target, error, bias, settings, seen.frame)
    sensed = replace(seen, flow=seen.flow + flow_error, velocity=seen.velocity + flow_error, to_target=to_target)
    if settings.gradient_noisy and seen.body_flow_gradient is not None:
        gradient_error = reading_error(GRADIENT_SENSOR, error, bias, settings).view(-1, 3, 3)
        sensed = replace(sensed, body_flow_gradient=seen.body_flow_gradient + gradient_error)
    return sensed


# From starts upstream of this x (the cylinder's side of the paper's regions) the paper's teacher reaches the
# extended domain's target in 59% of 4,000 episodes, the flow-compensating expert in 96% (docs/generalist.md).
UPSTREAM_X = 4.0
# The codes of paper_scene: which expert of a scene-routed teacher labels a swimmer (flownav/agents/scene_router.py).
SCENE_NONE, SCENE_PAPER, SCENE_UPSTREAM, SCENE_REVERSE, SCENE_AWAY, SCENE_WAKE, SCENE_CURRENT = 0, 1, 2, 3, 4, 5, 6
SCENE_POSED, SCENE_FREE, SCENE_WAKE_REGIONS = 7, 8, 9


def paper_scene(state: Swimmers, flow: FlowField, settings: Settings, idx: Tensor | None = None) -> Tensor:
    """Code of the paper's scene, for every slot (``[B]``) or the slots ``idx``: the CFD wake as posed (unturned:
    no misalignment, a family slot drawn without rotation, scaling or background; at strength 1) with the swimmer
    at its full speed, and SCENE_PAPER: the target in Region 2 from a start in Region 1 (the paper's training
    task); SCENE_UPSTREAM: that target for an episode that started upstream of ``UPSTREAM_X``; SCENE_AWAY: that
    target from any other start (the rest of the extended domain); SCENE_REVERSE: from Region 2 to a target in
    Region 1 (the crossing the other way, paper SI 2); SCENE_POSED: any other task of a full-speed swimmer in a
    family slot whose flow is the wake as posed; SCENE_WAKE: any other episode of a full-speed swimmer in a family
    slot whose flow holds an obstacle (a CFD wake or a vortex street; turned, scaled or on a current), and
    SCENE_WAKE_REGIONS where that episode is the paper's task (a start in Region 1, the target in Region 2);
    SCENE_CURRENT: an episode in a family slot whose flow is a uniform current or still water; SCENE_FREE: an
    episode of a full-speed swimmer in any other family slot (a random flow, one on a current); else SCENE_NONE.
    What the simulator knows and a scene-routed teacher reads."""
    slots = torch.arange(state.pos.shape[0], device=state.pos.device) if idx is None else idx
    start, target = state.start[slots], state.target[slots]
    if isinstance(flow, FlowFamily):
        posed, wake, current = flow.wake_as_posed(slots), flow.holds_obstacle(slots), flow.holds_uniform(slots)
        free = ~(wake | current)
    else:  # a misaligned scene is a RotatedFlow, not the dataset's GridFlow
        posed = torch.full_like(slots, isinstance(flow, GridFlow) and bool(flow.obstacles), dtype=torch.bool)
        wake = current = free = torch.zeros_like(posed)
    if settings.flow_strength is not None:
        posed = posed & (state.strength[slots] == 1)
    full = state.swim_scale[slots] == 1
    posed, wake, free = posed & full, wake & full, free & full
    from_1, to_2 = REGION_1.contains(start), REGION_2.contains(target)
    forward = posed & to_2
    reverse = posed & REGION_1.contains(target) & REGION_2.contains(start)
    code = torch.where(from_1, SCENE_PAPER, SCENE_AWAY)
    code = torch.where(start[:, 0] < UPSTREAM_X, SCENE_UPSTREAM, code)
    other = torch.where(free, SCENE_FREE, SCENE_NONE)
    regions = from_1 & to_2
    other = torch.where(
        wake, torch.where(regions, SCENE_WAKE_REGIONS, SCENE_WAKE), torch.where(current, SCENE_CURRENT, other)
    )
    other = torch.where(posed & wake, SCENE_POSED, other)
    code = torch.where(forward, code, other)
    return torch.where(reverse, SCENE_REVERSE, code)


def ring_history(ring: Tensor, ring_ptr: int) -> Tensor:
    """A memory ring's samples HISTORY_STRIDE steps apart, newest (now) first: ``[B, HISTORY_LEN, 3]``."""
    lags = torch.arange(HISTORY_LEN, device=ring.device) * HISTORY_STRIDE
    return ring[:, (ring_ptr - lags) % ring.shape[1]]


def flow_phase(state: Swimmers, flow: FlowField) -> Tensor | None:
    """Where each swimmer's flow is in its period, in [0, 1); None for a flow without one."""
    return torch.remainder((state.t0 + state.time) / flow.period, 1.0) if flow.period else None
