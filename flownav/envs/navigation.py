"""The batched TorchRL navigation environment: B swimmers, one tensor step for all.

A thin adapter of the physics in :mod:`flownav.envs.core` (state, episodes, step, observations): TorchRL specs,
TensorDicts in and out, reset masks, the random stream and ``state_dict`` for an exact resume.

Episodes end by termination (success within ``success_radius``, leaving the domain,
entering an obstacle) or by truncation at ``time_limit``; the ``status`` entry says which
(see :class:`Status`). Partial resets go through ``_reset`` with a ``"_reset"`` mask.
"""

from __future__ import annotations

import torch
from tensordict import TensorDict, TensorDictBase
from torch import Tensor
from torchrl.data import Bounded, Categorical, Composite, Unbounded
from torchrl.envs import EnvBase

from flownav.envs import core
from flownav.envs.core import DPSI_MAX, DTHETA_MAX, SAVED_FIELDS, STATE_FIELDS, Settings, Status
from flownav.envs.observations import check_views, observation_size
from flownav.envs.reward import RewardConfig
from flownav.envs.tasks import RegionTask
from flownav.flows.base import FlowField
from flownav.flows.families import FlowFamily

__all__ = ["DPSI_MAX", "DTHETA_MAX", "NavigationEnv", "Status"]


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
        sensor_noise: ``(flow, target, gradient)``: standard deviations of the ego views' sensors, fresh each step:
            the flow reading's error per component (velocity units), the to-target vector's relative to its length,
            the body-axis gradient's per component (``ego_mem_grad``; velocity per unit length)
            (:func:`flownav.envs.core.draw_sensor_error`). The geo and privileged views stay exact.
        sensor_bias: ``(flow, target, gradient)``: standard deviations of the same sensors' errors drawn once per
            episode (a steady bias, added to the errors of ``sensor_noise``): the gradient's per body-axis component,
            the flow reading's and the to-target vector's fixed in ``sensor_bias_frame``: ``"world"`` (a phantom
            steady current, a drifting bearing reference) or ``"body"`` (turning with the swimmer: a sensor's
            mounting offset).
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
        sensor_noise: tuple[float, float, float] = (0.0, 0.0, 0.0),
        sensor_bias: tuple[float, float, float] = (0.0, 0.0, 0.0),
        sensor_bias_frame: str = "world",
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
        sensor_noise, sensor_bias = (tuple(float(v) for v in sd) for sd in (sensor_noise, sensor_bias))
        for name, sd in (("sensor_noise", sensor_noise), ("sensor_bias", sensor_bias)):
            if len(sd) != 3 or not all(v >= 0 for v in sd):
                raise ValueError(f"{name} is (flow, target, gradient), three standard deviations >= 0; got {sd}")
        if sensor_bias_frame not in ("world", "body"):
            raise ValueError(f"sensor_bias_frame is 'world' or 'body'; got {sensor_bias_frame!r}")
        if reward is not None and not isinstance(reward, RewardConfig):
            raise ValueError(f"reward is a RewardConfig (flownav.envs.reward) or None; got {reward!r}")
        super().__init__(device=device, batch_size=torch.Size([num_envs]))
        self.num_envs, self.views, self.time_limit = num_envs, check_views(views), float(time_limit)
        self.settings = Settings(
            task=task if task is not None else RegionTask(),
            views=self.views,
            dt=float(dt),
            # Episodes are truncated after a whole number of steps; time is that count times dt (no float drift).
            max_steps=max(1, round(self.time_limit / float(dt))),
            u_max=float(u_max),
            swim_speed_scale=float(swim_speed_scale),
            reward=reward or RewardConfig(),
            misalignment_deg=float(misalignment_deg),
            rotation_center=tuple(rotation_center),
            random_flow_phase=random_flow_phase,
            flow_strength=flow_strength,
            flow_strength_full=float(flow_strength_full),
            sensor_noise=sensor_noise,
            sensor_bias=sensor_bias,
            sensor_bias_frame=sensor_bias_frame,
        )
        self.flow = core.scene_flow(flow, self.settings, num_envs, self.device)
        self._make_specs()
        self.state = core.initial_state(num_envs, self.settings, self.device)
        self.rng = torch.Generator(device=self.device)
        self.set_seed(0 if seed is None else seed)

    # The settings under the names evaluation code reads them by.
    dt = property(lambda self: self.settings.dt)
    max_steps = property(lambda self: self.settings.max_steps)
    u_max = property(lambda self: self.settings.u_max)
    swim_speed_scale = property(lambda self: self.settings.swim_speed_scale)
    reward_cfg = property(lambda self: self.settings.reward)

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
        low, high = core.action_bounds(self.settings, dev)
        self.action_spec = Bounded(low=low.expand(B, 3), high=high.expand(B, 3), shape=(B, 3), device=dev)
        self.reward_spec = Unbounded(shape=(B, 1), device=dev)
        self.done_spec = Composite(
            done=Categorical(2, shape=(B, 1), dtype=torch.bool, device=dev),
            terminated=Categorical(2, shape=(B, 1), dtype=torch.bool, device=dev),
            truncated=Categorical(2, shape=(B, 1), dtype=torch.bool, device=dev),
            shape=(B,),
            device=dev,
        )

    def _set_seed(self, seed: int | None):
        self.rng.manual_seed(int(seed) if seed is not None else 0)

    # ----------------------------------------------------------------- exact resume
    def state_dict(self) -> dict:
        """Everything a step depends on: the swimmers' state, the memory ring and its pointer, the RNG (the scene
        code follows from them: :meth:`load_state_dict` rebuilds it)."""
        state = {k: getattr(self.state, k) for k in SAVED_FIELDS}
        if isinstance(self.flow, FlowFamily):  # each slot's flow
            state["flow_family"] = self.flow.state_dict()
        return state | {"num_envs": self.num_envs, "rng": self.rng.get_state()}

    def load_state_dict(self, state: dict) -> None:
        """Continue exactly where :meth:`state_dict` was taken (an env built with the same settings)."""
        ring = self.state.flow_ring
        if state["num_envs"] != self.num_envs or state["flow_ring"].shape != ring.shape:
            raise ValueError(
                f"the saved env state has {state['num_envs']} swimmers and a memory ring of "
                f"{tuple(state['flow_ring'].shape)}; this env has {self.num_envs} and {tuple(ring.shape)}"
            )
        width = self.settings.sensor_error_width
        for key in ("sensor_error", "sensor_bias"):
            if key in state and state[key].shape[-1] != width:
                raise ValueError(
                    f"the saved env state holds {state[key].shape[-1]} sensor errors per swimmer, this env {width}: "
                    "build it with the saved run's env.sensor_noise and sensor_bias (a gradient error needs 15, else 6)"
                )
        # Env states saved before sensor errors, geo_priv_around, the body-axis gradient or the track views existed
        # hold no sensor_error or sensor_bias (exact sensors: zeros), flow_around or target_ring (no view read them)
        # or body_flow_grad (zeros until the next step senses it: an ego_mem_grad run saved then read the inertial
        # gradient and resumes only approximately).
        keep = ("sensor_error", "sensor_bias", "flow_around", "body_flow_grad", "target_ring")
        state = {k: getattr(self.state, k) for k in keep} | dict(state)
        saved = {k: state[k].to(self.device).clone() if torch.is_tensor(state[k]) else state[k] for k in SAVED_FIELDS}
        self.state = core.Swimmers(**saved, scene=self.state.scene)
        if isinstance(self.flow, FlowFamily):
            self.flow.load_state_dict(state["flow_family"])
        every = torch.arange(self.num_envs, device=self.device)
        self.state = core.keep_scene(self.state, self.flow, self.settings, every)
        self.rng.set_state(state["rng"])

    def _flow_at(self, pos: Tensor, t: Tensor, idx: Tensor | None = None) -> Tensor:
        """The flow velocity each swimmer feels: the flow's, times its episode's strength (all or ``idx``)."""
        return core.flow_at(self.flow, self.settings, self.state.strength, pos, t, idx)

    # ----------------------------------------------------------------- TorchRL API
    def _reset(self, tensordict: TensorDictBase | None = None, keep_state: bool = False, **kwargs) -> TensorDictBase:
        if not keep_state:  # keep_state: the observation of the current (e.g. just restored) state
            mask = None
            if tensordict is not None and "_reset" in tensordict.keys():
                mask = tensordict.get("_reset").reshape(self.num_envs)
            idx = torch.arange(self.num_envs, device=self.device) if mask is None else mask.nonzero().squeeze(-1)
            self.state = core.reset(self.state, idx, self.flow, self.settings, self.rng)
        false = torch.zeros(self.num_envs, 1, dtype=torch.bool, device=self.device)
        return self._observe().update({"done": false, "terminated": false.clone(), "truncated": false.clone()})

    def _step(self, tensordict: TensorDictBase) -> TensorDictBase:
        self.state, reward = core.step(self.state, tensordict.get("action"), self.flow, self.settings, self.rng)
        truncated = (self.state.status == Status.TIMEOUT)[:, None]
        terminated = (self.state.status != Status.RUNNING)[:, None] & ~truncated
        out = self._observe()
        done = {"done": terminated | truncated, "terminated": terminated, "truncated": truncated}
        return out.update({"reward": reward[:, None], **done})

    def _observe(self) -> TensorDict:
        s = self.state
        data = core.observe(s, self.flow, self.settings)
        data.update(
            position=s.pos,
            target=s.target,
            velocity=s.vel,
            heading=torch.stack((s.theta, s.psi), -1),
            time=s.time[:, None],
            status=s.status[:, None],
        )
        return TensorDict(data, batch_size=self.batch_size, device=self.device)


def _state_field(name: str) -> property:
    """``env.<name>``: the state's field, read and written (planners and tests read positions, set headings)."""
    return property(lambda env: getattr(env.state, name), lambda env, value: setattr(env.state, name, value))


for _name in STATE_FIELDS:
    setattr(NavigationEnv, _name, _state_field(_name))
