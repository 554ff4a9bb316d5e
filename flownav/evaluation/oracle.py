"""A full-knowledge receding-horizon planner: the reference that gives every success rate its meaning.

The oracle is privileged: it reads the environment's true state (position, heading, target, flow time,
the episode's flow strength) and the true flow, and plans by simulation. Its numbers say what is
achievable in a task; they are upper references found by a finite search, not bounds.

Plan: for each swimmer, ``candidates`` sequences of ``blocks`` equal blocks over ``horizon`` steps, each
block a desired heading (a unit vector) and a swim speed in [0, u_max]. A heading is flown by turning
towards it as fast as the turn-rate bounds allow, so every plan is an action sequence the env accepts.
All candidates of all swimmers are simulated as one batch through the env's own kinematics
(:func:`~flownav.envs.kinematics.turn`, :func:`~flownav.envs.kinematics.move`, success along the step,
the domain's wrap and minimum image) for ``iterations`` rounds of the cross-entropy method (the elites'
mean and spread seed the next round). The previous best plan, shifted by the steps since it was made, is
always a candidate: the flow is deterministic and the simulation is the env's, so a plan that reaches the
target keeps reaching it until a better one is found.
The best plan is followed for ``replan_every`` steps, then the search starts again.

Cost of a candidate (lower is better):
    reaches the target (segment against sphere) at step s:  -reach_bonus + s dt
    leaves the domain or enters an obstacle at step s:      +leave_penalty - s dt
    otherwise:                                              distance to the target after the horizon
                                                            (minimum image on periodic axes)
Steps past the episode's time limit count for nothing.

What the planner knows (``forecast``, ``sensing_radius``, ``knows_walls``): by default the true flow everywhere and
at every future time. With ``forecast=False`` it plans in the flow frozen at the time of planning (a snapshot, no
forecast); with a ``sensing_radius`` R it knows the flow only within R of the swimmer at planning time (minimum
image) and assumes the flow it feels there everywhere beyond. With ``knows_walls=False`` it does not know where the
domain ends (an ego view has no position): a plan that leaves the domain is judged as if the domain went on. The env
moves the swimmer in the true flow either way: what a navigator with that much knowledge of the flow could plan by
this search, the references of a policy that senses less than all.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch
from torch import Tensor

from flownav.envs.core import flow_at, flow_of_rows, in_obstacle
from flownav.envs.kinematics import heading_vector, move, step_reaches, turn, wrap_angle
from flownav.envs.navigation import DPSI_MAX, DTHETA_MAX, NavigationEnv


@dataclass(frozen=True)
class OracleSettings:
    candidates: int = 64  # sampled plans per swimmer and round
    horizon: int = 60  # steps looked ahead (12 time units at dt = 0.2)
    blocks: int = 3  # piecewise-constant heading/speed blocks per plan
    iterations: int = 3  # cross-entropy rounds per replan
    elites: int = 6  # best candidates that set the next round's distribution
    replan_every: int = 5  # steps between replans
    reach_bonus: float = 1000.0
    leave_penalty: float = 1000.0
    forecast: bool = True  # plans in the flow as it will be; False: in the flow frozen at planning time
    sensing_radius: float | None = None  # known flow within this distance of the swimmer; None: everywhere
    knows_walls: bool = True  # False: a plan that leaves the domain costs nothing extra (obstacles still do)
    seed: int = 0

    def __post_init__(self):
        ints = ("candidates", "horizon", "blocks", "iterations", "elites", "replan_every")
        bad = [k for k in ints if int(getattr(self, k)) < 1]
        order = self.elites <= self.candidates >= 3 and self.blocks <= self.horizon >= self.replan_every
        if bad or not order or (self.sensing_radius is not None and not self.sensing_radius > 0):
            raise ValueError(
                f"oracle settings need {', '.join(ints)} >= 1, candidates >= 3, elites <= candidates, "
                f"blocks <= horizon, replan_every <= horizon and sensing_radius > 0 (or null); got {self}"
            )


class Oracle:
    """Privileged policy: ``act_privileged(env, slots) -> actions [len(slots), 3]`` (see run_episodes)."""

    def __init__(self, **settings):
        self.settings = OracleSettings(**settings)
        self.generator = torch.Generator().manual_seed(self.settings.seed)
        self._env = None

    def __call__(self, obs: Tensor) -> Tensor:
        raise TypeError("the oracle plans from the env's true state: run it through run_episodes (act_privileged)")

    # ----------------------------------------------------------------- the hook run_episodes calls
    @torch.inference_mode()
    def act_privileged(self, env: NavigationEnv, slots: Tensor) -> Tensor:
        s = self.settings
        if env is not self._env:  # a new chunk of episodes: forget the old plans and restart the search's draws,
            self._env = env  # so that an evaluation's result does not depend on what the oracle planned before it
            self.generator.manual_seed(s.seed)
            B = env.num_envs
            self.plan = torch.zeros(B, s.horizon, 4, device=env.device)  # per step: heading (3), speed
            self.age = torch.full((B,), s.replan_every, dtype=torch.long)  # steps since the plan was made
            self.fresh = torch.ones(B, dtype=torch.bool)  # no plan yet
        slots = slots.cpu()
        due = slots[self.age[slots] >= s.replan_every]
        if due.numel():
            self._replan(env, due.to(env.device))
            self.age[due] = 0
            self.fresh[due] = False
        step = self.plan[slots.to(env.device), self.age[slots].to(env.device)]
        self.age[slots] += 1
        return self._steer(env, env.theta[slots], env.psi[slots], step)

    # ----------------------------------------------------------------- planning
    def _steer(self, env, theta: Tensor, psi: Tensor, step: Tensor) -> Tensor:
        """The action that turns (theta, psi) towards the desired heading as fast as allowed, at the plan's speed."""
        d = step[..., :3]
        theta_d = torch.atan2(d[..., 1], d[..., 0])
        psi_d = torch.asin(d[..., 2].clamp(-1, 1))
        dtheta = (wrap_angle(theta_d - theta) / env.dt).clamp(-DTHETA_MAX, DTHETA_MAX)
        dpsi = ((psi_d - psi) / env.dt).clamp(-DPSI_MAX, DPSI_MAX)
        return torch.stack((step[..., 3].clamp(0, 1) * env.u_max, dtheta, dpsi), -1)

    def _replan(self, env: NavigationEnv, idx: Tensor) -> None:
        s, dev = self.settings, env.device
        m, K, J, H = idx.numel(), s.candidates, s.blocks, s.horizon
        to_target = env.flow.displacement(env.pos[idx], env.target[idx])
        unit = to_target / to_target.norm(dim=-1, keepdim=True).clamp_min(1e-9)
        straight = torch.cat((unit, torch.ones(m, 1, device=dev)), -1)[:, None, :].expand(m, H, 4)
        # The previous plan shifted by its age, its last step repeated (straight at the target if none).
        shift = self.age[idx.cpu()].to(dev).clamp(max=H - 1)
        at = (torch.arange(H, device=dev)[None, :] + shift[:, None]).clamp(max=H - 1)
        prev = torch.gather(self.plan[idx], 1, at[:, :, None].expand(m, H, 4))
        prev = torch.where(self.fresh[idx.cpu()].to(dev)[:, None, None], straight, prev)
        starts = torch.arange(J, device=dev) * H // J  # first step of each block
        mean, std = prev[:, starts], torch.full((m, J, 4), 1.0, device=dev)
        best, best_cost = prev, torch.full((m,), math.inf, device=dev)
        for it in range(s.iterations):
            noise = torch.randn(m, K, J, 4, generator=self.generator).to(dev)
            cand = self._per_step(self._normalise(mean[:, None] + std[:, None] * noise), H)
            if it == 0:  # keep the previous plan, straight at the target, and pure drift among the candidates
                cand[:, 0], cand[:, 1] = prev, straight
                cand[:, 2, :, 3] = 0.0
            cost = self._rollout(env, idx, cand)
            order = cost.argsort(dim=1)[:, : s.elites]
            elite = torch.gather(cand, 1, order[:, :, None, None].expand(m, s.elites, H, 4))
            mean, std = elite[:, :, starts].mean(1), elite[:, :, starts].std(1).clamp_min(0.05)
            c0 = torch.gather(cost, 1, order[:, :1]).squeeze(1)
            best = torch.where((c0 < best_cost)[:, None, None], elite[:, 0], best)
            best_cost = torch.minimum(best_cost, c0)
        self.plan[idx] = best

    @staticmethod
    def _normalise(cand: Tensor) -> Tensor:
        head = cand[..., :3] / cand[..., :3].norm(dim=-1, keepdim=True).clamp_min(1e-9)
        return torch.cat((head, cand[..., 3:].clamp(0, 1)), -1)

    @staticmethod
    def _per_step(blocks: Tensor, H: int) -> Tensor:
        """[..., J, 4] blocks -> [..., H, 4] steps."""
        J = blocks.shape[-2]
        which = (torch.arange(H, device=blocks.device) * J) // H
        return blocks[..., which, :]

    def _rollout(self, env: NavigationEnv, idx: Tensor, cand: Tensor) -> Tensor:
        """Cost of every candidate plan ``[m, K, H, 4]``, all simulated as one batch: ``[m, K]``."""
        s = self.settings
        m, K = cand.shape[:2]
        rep = idx.repeat_interleave(K)  # env slot of each simulated swimmer
        # The slots' flows and strengths gathered once for all steps.
        flow = flow_of_rows(env.flow, rep)
        strength = env.state.strength[rep]
        pos, target = env.pos[rep], env.target[rep]
        theta, psi = env.theta[rep], env.psi[rep]
        flow_vel, t0, steps0 = env.flow_vel[rep], env.t0[rep], env.steps[rep]
        here, felt = pos, flow_vel  # where the plan starts and the flow felt there (what a sensor reads now)
        plan = cand.reshape(m * K, *cand.shape[2:])
        remaining = (env.max_steps - steps0).clamp_min(0)
        radius = env.reward_cfg.success_radius
        cost = torch.zeros(m * K, device=pos.device)
        alive = torch.ones(m * K, dtype=torch.bool, device=pos.device)
        for h in range(s.horizon):
            live = alive & (h < remaining)
            if not live.any():
                break
            speed, dtheta, dpsi = self._steer(env, theta, psi, plan[:, h]).unbind(-1)
            theta, psi = turn(theta, psi, dtheta, dpsi, env.dt)
            swim = (speed * env.swim_speed_scale)[:, None] * heading_vector(theta, psi)
            new, _ = move(pos, swim, flow_vel, env.dt)
            reached = live & step_reaches(env.flow.displacement(pos, target), new - pos, radius)
            pos = torch.where(live[:, None], env.flow.wrap(new), pos)
            flow_vel = flow_at(flow, env.settings, strength, pos, t0 + (steps0 + (h + 1 if s.forecast else 0)) * env.dt)
            if s.sensing_radius is not None:
                unseen = env.flow.displacement(here, pos).norm(dim=-1) > s.sensing_radius
                flow_vel = torch.where(unseen[:, None], felt, flow_vel)
            blocked = in_obstacle(flow, pos)
            if s.knows_walls:
                blocked = blocked | ~env.flow.in_domain(pos)
            out = live & ~reached & blocked
            t = (h + 1) * env.dt
            cost = torch.where(reached, t - s.reach_bonus, cost)
            cost = torch.where(out, s.leave_penalty - t, cost)
            alive = alive & ~reached & ~out
        final = env.flow.displacement(pos, target).norm(dim=-1)
        cost = torch.where(alive, final, cost)
        return cost.reshape(m, K)
