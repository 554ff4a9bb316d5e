"""The batched TorchRL navigation environment: B swimmers, one tensor step for all.

State per swimmer: position, heading (theta, psi), target, episode time, flow-time offset,
start distance and the velocity it currently has. A step turns the heading, moves every
swimmer with swim + flow velocity (eq. 1-3), then looks the flow up once at the new
positions: that value is both the flow the next step moves with and the flow the
observations report, so each step costs exactly one flow look-up.

Episodes end by termination (success within ``success_radius``, leaving the domain,
entering an obstacle) or by truncation at ``time_limit``; the ``status`` entry says which
(see :class:`Status`). Partial resets go through ``_reset`` with a ``"_reset"`` mask.
"""

from __future__ import annotations

import math
from enum import IntEnum

import torch
from tensordict import TensorDict, TensorDictBase
from torch import Tensor
from torchrl.data import Bounded, Categorical, Composite, Unbounded
from torchrl.envs import EnvBase

from flownav.envs.kinematics import body_frame, heading_vector, move, step_reaches, turn, wrap_angle
from flownav.envs.observations import (
    HISTORY_LEN,
    HISTORY_STRIDE,
    State,
    check_views,
    compute_views,
    needs_body_frame,
    needs_gradient,
    needs_history,
    needs_phase,
    needs_target_flow,
    observation_size,
)
from flownav.envs.reward import RewardConfig, step_reward
from flownav.envs.tasks import RegionTask
from flownav.errors import require_finite
from flownav.flows.base import FlowField
from flownav.flows.families import FlowFamily
from flownav.flows.transforms import RotatedFlow, rotate_z

# Action bounds of the paper (section 2.3.2): U in [0, U_max], dtheta, dpsi in rad per time unit.
DTHETA_MAX = math.pi / 4
DPSI_MAX = math.pi / 2
FLOW_FIX = "the flow must be finite over the whole domain (a FunctionFlow's function, a dataset's frames)"
# Forward-difference step of the privileged views' flow gradient (below the wake grid's spacing 0.25).
GRADIENT_STEP = 0.05


class Status(IntEnum):
    RUNNING = 0
    SUCCESS = 1
    LEFT_DOMAIN = 2
    HIT_OBSTACLE = 3
    TIMEOUT = 4


class NavigationEnv(EnvBase):
    """Point-to-point navigation of ``num_envs`` swimmers in a flow.

    Args:
        flow: any :class:`~flownav.flows.FlowField`.
        task: a sampler of (start, target) pairs (default: the paper's Region 1 -> Region 2).
        num_envs: batch size B.
        views: observation views to emit, names of :data:`flownav.envs.observations.VIEWS` (``geo_sincos``,
            ``ego``, ``ego_up``, ...).
        dt: time step; time_limit: episode length in time units (truncation).
        u_max: the action's speed bound; swim_speed_scale multiplies the speed the swimmer
            really gets (0.1 in the ABC test, where the policy still acts in [0, u_max]). A task with a
            ``swim_speed(n, generator, device)`` method draws a further factor per episode.
        misalignment_deg: rotate the whole scene (flow, domain, obstacles, starts, targets,
            headings) about z through ``rotation_center``: the misaligned-wake test.
        random_flow_phase: start each episode at a random time of a periodic flow.
        flow_strength: ``(low, high)``: each episode multiplies the flow's velocity by a factor drawn
            uniformly in [low, high] (0: still water), so a policy meets weak and strong versions of the
            flow; None: the flow as it is. The strength is drawn after the episode's other draws, so the
            first reset's starts, targets and headings are those of an env without it (later ones differ).
        flow_strength_full: the fraction of episodes that get the flow at full strength (1) instead of a
            draw in ``flow_strength``, so the hardest case keeps its weight in training.
    """

    batch_locked = True

    def __init__(
        self,
        flow: FlowField,
        task=None,
        num_envs: int = 1024,
        views=("geo", "ego"),
        dt: float = 0.2,
        time_limit: float = 60.0,
        u_max: float = 1.0,
        swim_speed_scale: float = 1.0,
        reward: RewardConfig | None = None,
        misalignment_deg: float = 0.0,
        rotation_center: tuple[float, float] = (0.0, 0.0),
        random_flow_phase: bool = True,
        flow_strength: tuple[float, float] | None = None,
        flow_strength_full: float = 0.0,
        seed: int | None = 0,
        device="cpu",
    ):
        if num_envs < 1 or not dt > 0 or not time_limit > 0 or not u_max > 0 or not swim_speed_scale > 0:
            raise ValueError(
                f"need num_envs >= 1, dt > 0, time_limit > 0, u_max > 0, swim_speed_scale > 0; got "
                f"num_envs={num_envs}, dt={dt}, time_limit={time_limit}, u_max={u_max}, "
                f"swim_speed_scale={swim_speed_scale}"
            )
        if flow_strength is not None:
            flow_strength = tuple(float(f) for f in flow_strength)
            if len(flow_strength) != 2 or not 0 <= flow_strength[0] <= flow_strength[1]:
                raise ValueError(f"flow_strength must be [low, high] with 0 <= low <= high, got {flow_strength}")
        if not 0 <= flow_strength_full <= 1:
            raise ValueError(f"flow_strength_full is a fraction in [0, 1], got {flow_strength_full}")
        if flow_strength_full and flow_strength is None:
            raise ValueError("flow_strength_full needs flow_strength=[low, high] (the draw it replaces)")
        self.flow_strength, self.flow_strength_full = flow_strength, float(flow_strength_full)
        super().__init__(device=device, batch_size=torch.Size([num_envs]))
        self.views = check_views(views)
        self._ego = needs_body_frame(self.views)
        self._memory = needs_history(self.views)
        self._phase = needs_phase(self.views)
        # Privileged views: the flow's gradient (and the flow at the target), sensed once per step.
        self._gradient, self._target_flow = needs_gradient(self.views), needs_target_flow(self.views)
        self.angle = math.radians(misalignment_deg)
        self.rotation_center = tuple(rotation_center)
        base = flow.to(self.device)
        self.flow = RotatedFlow(base, misalignment_deg, rotation_center) if misalignment_deg else base
        # A flow family holds one flow per slot, drawn at each reset (it draws its own rotations).
        self._family = isinstance(base, FlowFamily)
        if self._family:
            if misalignment_deg:
                raise ValueError("misalignment_deg rotates one flow; a flow family draws its own rotations (angle_deg)")
            base = self.flow = base.bind(num_envs, self.device)
        self.task = task if task is not None else RegionTask()
        self.dt, self.time_limit = float(dt), float(time_limit)
        # Episodes are truncated after a whole number of steps; time is that count times dt (no float drift).
        self.max_steps = max(1, round(self.time_limit / self.dt))
        self.u_max, self.swim_speed_scale = float(u_max), float(swim_speed_scale)
        self.reward_cfg = reward or RewardConfig()
        self.random_flow_phase = random_flow_phase
        self.num_envs = num_envs
        self._make_specs()
        self._alloc_state()
        self.rng = torch.Generator(device=self.device)
        self.set_seed(0 if seed is None else seed)

    # ----------------------------------------------------------------- specs and state
    def _make_specs(self):
        B, dev = self.num_envs, self.device
        obs = {v: Unbounded(shape=(B, observation_size(v)), device=dev) for v in self.views}
        obs.update(
            position=Unbounded(shape=(B, 3), device=dev),
            target=Unbounded(shape=(B, 3), device=dev),
            velocity=Unbounded(shape=(B, 3), device=dev),
            heading=Unbounded(shape=(B, 2), device=dev),
            time=Unbounded(shape=(B, 1), device=dev),
            status=Categorical(len(Status), shape=(B, 1), dtype=torch.int64, device=dev),
        )
        self.observation_spec = Composite(obs, shape=(B,), device=dev)
        self.action_spec = Bounded(
            low=torch.tensor([0.0, -DTHETA_MAX, -DPSI_MAX], device=dev).expand(B, 3),
            high=torch.tensor([self.u_max, DTHETA_MAX, DPSI_MAX], device=dev).expand(B, 3),
            shape=(B, 3),
            device=dev,
        )
        self.reward_spec = Unbounded(shape=(B, 1), device=dev)
        self.done_spec = Composite(
            done=Categorical(2, shape=(B, 1), dtype=torch.bool, device=dev),
            terminated=Categorical(2, shape=(B, 1), dtype=torch.bool, device=dev),
            truncated=Categorical(2, shape=(B, 1), dtype=torch.bool, device=dev),
            shape=(B,),
            device=dev,
        )

    def _alloc_state(self):
        B, dev = self.num_envs, self.device
        z = lambda *s: torch.zeros(B, *s, device=dev)  # noqa: E731
        self.pos, self.target, self.vel, self.flow_vel = z(3), z(3), z(3), z(3)
        self.theta, self.psi, self.time, self.t0 = z(), z(), z(), z()
        self.strength = torch.ones(B, device=dev)  # the episode's factor on the flow (flow_strength)
        self.swim_scale = torch.full((B,), self.swim_speed_scale, device=dev)  # per slot: tasks may draw it
        self.flow_grad, self.target_flow = torch.zeros(B, 3, 3, device=dev), z(3)  # privileged views only
        self.start_dist, self.dist, self.speed = z(), z(), z()
        self.status = torch.zeros(B, dtype=torch.int64, device=dev)
        self.steps = torch.zeros(B, dtype=torch.int64, device=dev)
        # Memory views: a ring of the last (HISTORY_LEN - 1) * HISTORY_STRIDE + 1 flow samples. All swimmers
        # step together, so one pointer serves the batch; a reset swimmer's ring is refilled with its start flow.
        ring = (HISTORY_LEN - 1) * HISTORY_STRIDE + 1 if self._memory else 0
        self.flow_ring = torch.zeros(B, ring, 3, device=dev)
        self.ring_ptr = 0
        self.ring_lags = torch.arange(HISTORY_LEN, device=dev) * HISTORY_STRIDE

    def _set_seed(self, seed: int | None):
        self.rng.manual_seed(int(seed) if seed is not None else 0)

    # ----------------------------------------------------------------- exact resume
    STATE = ("pos", "target", "vel", "flow_vel", "theta", "psi", "time", "t0", "strength", "start_dist", "dist",
             "speed", "status", "steps", "flow_ring", "ring_ptr", "swim_scale", "flow_grad", "target_flow")  # fmt: skip

    def state_dict(self) -> dict:
        """Everything a step depends on: the swimmers' state, the memory ring and its pointer, the RNG."""
        state = {k: getattr(self, k) for k in self.STATE}
        if self._family:  # each slot's flow
            state["flow_family"] = self.flow.state_dict()
        return state | {"num_envs": self.num_envs, "rng": self.rng.get_state()}

    def load_state_dict(self, state: dict) -> None:
        """Continue exactly where :meth:`state_dict` was taken (an env built with the same settings)."""
        if state["num_envs"] != self.num_envs or state["flow_ring"].shape != self.flow_ring.shape:
            raise ValueError(
                f"the saved env state has {state['num_envs']} swimmers and a memory ring of "
                f"{tuple(state['flow_ring'].shape)}; this env has {self.num_envs} and {tuple(self.flow_ring.shape)}"
            )
        for k in self.STATE:
            v = state[k]
            setattr(self, k, v.to(self.device).clone() if torch.is_tensor(v) else v)
        if self._family:
            self.flow.load_state_dict(state["flow_family"])
        self.rng.set_state(state["rng"])

    # ----------------------------------------------------------------- sampling
    def _sample_episodes(self, n: int, idx: Tensor | None = None):
        """Starts, targets and headings for n new episodes (slots ``idx``), in the (possibly rotated) scene."""
        start, target = self.task.sample(n, self.rng, self.device)
        start, target = start.to(self.device, torch.float32), target.to(self.device, torch.float32)
        # Rejection: a start must lie in the domain, outside obstacles and outside the success ball.
        base_flow = self.flow.base if isinstance(self.flow, RotatedFlow) else self.flow
        for _ in range(100):
            bad = (
                ~base_flow.in_domain(start)
                | (base_flow.in_obstacle(start, idx) if self._family else base_flow.in_obstacle(start))
                | (base_flow.displacement(start, target).norm(dim=-1) <= self.reward_cfg.success_radius)
            )
            if not bad.any():
                break
            fresh, _ = self.task.sample(n, self.rng, self.device)
            start = torch.where(bad[:, None], fresh.to(start), start)
        else:
            raise ValueError("the task keeps sampling starts outside the domain or inside an obstacle")
        theta = (torch.rand(n, generator=self.rng, device=self.device) * 2 - 1) * math.pi
        psi = torch.asin(torch.rand(n, generator=self.rng, device=self.device) * 2 - 1)  # uniform on the sphere
        if self.angle:
            start = rotate_z(start, self.angle, self.rotation_center)
            target = rotate_z(target, self.angle, self.rotation_center)
            theta = theta + self.angle
        period = self.flow.period
        if self.random_flow_phase and period:
            t0 = torch.rand(n, generator=self.rng, device=self.device) * period
        else:
            t0 = torch.zeros(n, device=self.device)
        strength = None  # the flow as it is: self.strength stays 1 and is never read
        if self.flow_strength is not None:  # drawn last: this batch's other draws are those of an env without it
            low, high = self.flow_strength
            strength = low + (high - low) * torch.rand(n, generator=self.rng, device=self.device)
            if self.flow_strength_full:
                full = torch.rand(n, generator=self.rng, device=self.device) < self.flow_strength_full
                strength = torch.where(full, torch.ones_like(strength), strength)
        return start, target, wrap_angle(theta), psi, t0, strength

    def _flow_at(self, pos: Tensor, t: Tensor, idx: Tensor | None = None) -> Tensor:
        """The flow velocity each swimmer feels: the flow's, times its episode's strength (all or ``idx``)."""
        u = self.flow.velocity(pos, t, idx) if self._family else self.flow.velocity(pos, t)
        if self.flow_strength is None:
            return u
        s = self.strength if idx is None else self.strength[idx]
        return u * s[:, None]

    # ----------------------------------------------------------------- TorchRL API
    def _reset(self, tensordict: TensorDictBase | None = None, keep_state: bool = False, **kwargs) -> TensorDictBase:
        if keep_state:  # the observation of the current (e.g. just restored) state, no new episodes
            return self._observe().update(self._not_done())
        mask = None
        if tensordict is not None and "_reset" in tensordict.keys():
            mask = tensordict.get("_reset").reshape(self.num_envs)
        idx = torch.arange(self.num_envs, device=self.device) if mask is None else mask.nonzero().squeeze(-1)
        # Out of place: tensors returned by earlier steps must keep their values.
        put = lambda old, new: old.index_put((idx,), new)  # noqa: E731
        if idx.numel():
            if self._family:
                self.flow.resample(idx, self.rng)
            start, target, theta, psi, t0, strength = self._sample_episodes(idx.numel(), idx)
            if strength is not None:
                self.strength = put(self.strength, strength)
            if hasattr(self.task, "swim_speed"):  # drawn last: tasks without it keep their random streams
                swim = self.task.swim_speed(idx.numel(), self.rng, self.device)
                self.swim_scale = put(self.swim_scale, self.swim_speed_scale * swim)
            flow_vel = self._flow_at(start, t0, idx)
            require_finite(flow_vel, "the flow velocity at the start", FLOW_FIX, start)
            d = self.flow.displacement(start, target).norm(dim=-1)
            zero = torch.zeros_like(d)
            self.pos, self.target, self.theta, self.psi = (
                put(self.pos, start),
                put(self.target, target),
                put(self.theta, theta),
                put(self.psi, psi),
            )
            self.t0, self.time, self.speed = (
                put(self.t0, t0),
                put(self.time, zero),
                put(self.speed, zero),
            )
            self.status = put(self.status, torch.zeros_like(idx))
            self.steps = put(self.steps, torch.zeros_like(idx))
            # At rest relative to the fluid until the first action.
            self.flow_vel, self.vel = put(self.flow_vel, flow_vel), put(self.vel, flow_vel)
            self.start_dist, self.dist = put(self.start_dist, d), put(self.dist, d)
            if self._memory:  # no past yet: the swimmer has been sensing its start flow
                self.flow_ring[idx] = flow_vel[:, None, :]
            self._sense_privileged(idx)
        return self._observe().update(self._not_done())

    def _not_done(self) -> dict:
        false = torch.zeros(self.num_envs, 1, dtype=torch.bool, device=self.device)
        return {"done": false, "terminated": false.clone(), "truncated": false.clone()}

    def _step(self, tensordict: TensorDictBase) -> TensorDictBase:
        action = tensordict.get("action")
        require_finite(action, "the action", "the policy produced it: check its weights and observations")
        low, high = self.action_spec.space.low, self.action_spec.space.high
        action = torch.max(torch.min(action, high), low)
        speed, dtheta, dpsi = action.unbind(-1)
        self.theta, self.psi = turn(self.theta, self.psi, dtheta, dpsi, self.dt)
        self.speed = speed * self.swim_scale
        swim = self.speed[:, None] * heading_vector(self.theta, self.psi)
        prev_pos = self.pos
        self.pos, _ = move(self.pos, swim, self.flow_vel, self.dt)
        step = self.pos - prev_pos
        self.pos = self.flow.wrap(self.pos)  # periodic axes: back into the box
        self.steps = self.steps + 1
        self.time = self.steps * self.dt
        self.flow_vel = self._flow_at(self.pos, self.t0 + self.time)
        require_finite(self.flow_vel, "the flow velocity", FLOW_FIX, self.pos)
        self.vel = swim + self.flow_vel
        if self._memory:
            self.ring_ptr = (self.ring_ptr + 1) % self.flow_ring.shape[1]
            self.flow_ring[:, self.ring_ptr] = self.flow_vel
        self._sense_privileged()

        prev_dist = self.dist
        self.dist = self.flow.displacement(self.pos, self.target).norm(dim=-1)
        # Along the whole step, not only at its end: a fast step must not jump over the success ball.
        success = step_reaches(self.flow.displacement(prev_pos, self.target), step, self.reward_cfg.success_radius)
        left = ~self.flow.in_domain(self.pos)
        hit = self.flow.in_obstacle(self.pos)
        timeout = self.steps >= self.max_steps
        status = torch.full_like(self.status, Status.RUNNING)
        status = torch.where(timeout, Status.TIMEOUT, status)
        status = torch.where(hit, Status.HIT_OBSTACLE, status)
        status = torch.where(left, Status.LEFT_DOMAIN, status)
        self.status = torch.where(success, Status.SUCCESS, status)
        terminated = (success | left | hit)[:, None]
        truncated = timeout[:, None] & ~terminated
        reward = step_reward(self.reward_cfg, prev_dist, self.dist, self.start_dist, success, self.dt)
        require_finite(reward, "the reward", "check env.reward (alpha, success_bonus, time_penalty, ...)")
        out = self._observe()
        out.update(
            {
                "reward": reward[:, None],
                "done": terminated | truncated,
                "terminated": terminated,
                "truncated": truncated,
            }
        )
        return out

    def _flow_history(self) -> Tensor:
        """The flow HISTORY_STRIDE steps apart, newest (now) first: ``[B, HISTORY_LEN, 3]``."""
        return self.flow_ring[:, (self.ring_ptr - self.ring_lags) % self.flow_ring.shape[1]]

    def _flow_phase(self) -> Tensor | None:
        """Where each swimmer's flow is in its period, in [0, 1); None for a flow without one."""
        period = self.flow.period
        return torch.remainder((self.t0 + self.time) / period, 1.0) if period else None

    def _sense_privileged(self, idx: Tensor | None = None) -> None:
        """What only the simulator knows, for the privileged views, kept per slot (all or ``idx``): the flow's
        gradient by forward differences from the flow the swimmer feels and the flow at the target, in one
        look-up of 3 (or 4) points per swimmer."""
        if not self._gradient:
            return
        slots = torch.arange(self.num_envs, device=self.device) if idx is None else idx
        pos, t, n = self.pos[slots], (self.t0 + self.time)[slots], slots.numel()
        points = pos[None] + torch.eye(3, device=self.device)[:, None] * GRADIENT_STEP  # [3 (j), n, 3]: + h e_j
        if self._target_flow:
            points = torch.cat((points, self.target[slots][None]))
        rows = points.shape[0]
        u = self._flow_at(points.reshape(-1, 3), t.repeat(rows), slots.repeat(rows)).view(rows, n, 3)
        grad = ((u[:3] - self.flow_vel[slots]) / GRADIENT_STEP).permute(1, 2, 0)  # [n, i (component), j (d/dx_j)]
        self.flow_grad = self.flow_grad.index_put((slots,), grad)
        if self._target_flow:
            self.target_flow = self.target_flow.index_put((slots,), u[3])

    def _privileged_state(self) -> dict:
        if not self._gradient:
            return {}
        return {
            "flow_gradient": self.flow_grad,
            "target_flow": self.target_flow,
            "swim_speed": self.u_max * self.swim_scale,
            "time_left": 1 - self.steps / self.max_steps,
        }

    def _observe(self) -> TensorDict:
        state = State(
            to_target=self.flow.displacement(self.pos, self.target),
            velocity=self.vel,
            flow=self.flow_vel,
            theta=self.theta,
            psi=self.psi,
            frame=body_frame(self.theta, self.psi) if self._ego else None,  # skipped for geo-only runs
            flow_history=self._flow_history() if self._memory else None,
            flow_phase=self._flow_phase() if self._phase else None,
            **self._privileged_state(),
        )
        data = compute_views(state, self.views)
        data.update(
            position=self.pos,
            target=self.target,
            velocity=self.vel,
            heading=torch.stack((self.theta, self.psi), -1),
            time=self.time[:, None],
            status=self.status[:, None],
        )
        return TensorDict(data, batch_size=self.batch_size, device=self.device)
