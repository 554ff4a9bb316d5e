"""Gymnasium adapters of the batched :class:`~flownav.envs.navigation.NavigationEnv`.

* Observation: one view of :data:`flownav.envs.observations.VIEWS` (``geo_sincos``, ``ego``, ...), a float32
  ``Box`` without bounds, exactly the numbers the TorchRL env emits under that key.
* Action: ``[-1, 1]^3``, mapped affinely onto the paper's box, ``low + (high - low) (a + 1) / 2``: swim speed
  ``a0 -> [0, u_max]``, turn rates ``a1 -> dtheta in [-pi/4, pi/4]``, ``a2 -> dpsi in [-pi/2, pi/2]`` (rad per time
  unit). This is :class:`~flownav.agents.networks.SquashedAction` without its tanh: a project policy's action is
  this map of ``tanh`` of its network's output. Values outside ``[-1, 1]`` are clipped.
* Reward, termination (success, left the domain, hit the obstacle) and truncation (``time_limit``) are the TorchRL
  env's; ``terminated`` and ``truncated`` are never both true.
* ``info``: the privileged state the observation may hide: ``position``, ``target``, ``velocity`` (3 each,
  inertial frame), ``heading`` (theta, psi), ``time`` (since the episode's start), ``status`` (an
  :class:`~flownav.envs.navigation.Status`) and ``is_success`` (Stable-Baselines3 logs its rate).
* Seeding: ``reset(seed=s)`` seeds the TorchRL env's generator with ``s``, so the episodes are those of
  ``NavigationEnv(..., seed=s)`` (flownav.builders.build_env with ``seed=s``); ``reset()`` continues the stream, and
  a first ``reset()`` without a seed draws one from gymnasium's entropy-seeded ``np_random``.

The vector env steps all B swimmers in one call and resets finished ones in the same step (gymnasium's
``AutoresetMode.SAME_STEP``, TorchRL's ``step_and_maybe_reset``): the returned observation of a finished swimmer
starts its next episode, and ``info["final_obs"]`` / ``info["final_info"]`` hold the end of the finished one.
"""

from __future__ import annotations

from collections.abc import Mapping

import gymnasium
import numpy as np
import torch
from gymnasium import spaces
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space
from omegaconf import OmegaConf
from tensordict import TensorDict, TensorDictBase

from flownav.builders import build_env, build_flow, build_task
from flownav.envs.navigation import NavigationEnv, Status
from flownav.envs.observations import observation_size
from flownav.errors import ConfigError
from flownav.paths import REPO_ROOT

CONF_DIR = REPO_ROOT / "conf"
DEFAULT_VIEW = "geo_sincos"  # the teacher's view: plain RL (PPO) learns the task from it, not from ego (paper)


def group_config(group: str, value) -> dict:
    """A config of one of conf/'s groups: a name (``conf/<group>/<name>.yaml``) or a config dict, used as given."""
    if isinstance(value, Mapping) or OmegaConf.is_config(value):
        return OmegaConf.to_container(OmegaConf.create(value), resolve=True)
    path = CONF_DIR / group / f"{value}.yaml"
    if not path.is_file():
        choices = sorted(p.stem for p in (CONF_DIR / group).glob("*.yaml"))
        raise ConfigError(f"{group}={value!r}: no conf/{group}/{value}.yaml; pass one of {choices} or a config dict")
    return OmegaConf.to_container(OmegaConf.load(path), resolve=True)


def make_navigation_env(view: str, flow, task, num_envs: int, device="cpu", **env) -> NavigationEnv:
    """The TorchRL env the adapters wrap: ``flow`` / ``task`` as :func:`group_config` takes them, ``env`` keys
    overriding ``conf/env/default.yaml`` (``dt``, ``time_limit``, ``swim_speed_scale``, ``reward``, ...)."""
    env_cfg = group_config("env", "default")
    keys = sorted(k for k in env_cfg if k != "num_envs")
    unknown = sorted(set(env) - set(keys))
    if unknown:
        raise ConfigError(f"unknown env keyword(s) {unknown}; keys of conf/env/default.yaml: {keys}")
    env_cfg = OmegaConf.merge(env_cfg, env)
    flow_field = build_flow(group_config("flow", flow), device=device)
    sampler = build_task(group_config("task", task), flow_field)
    return build_env(env_cfg, flow_field, sampler, [view], num_envs=num_envs, device=device)


def _refuse_render(render_mode) -> None:
    if render_mode is not None:
        # TypeError, as for an unknown argument: SB3's make_vec_env then makes the env without render_mode.
        raise TypeError(f"render_mode={render_mode!r}: flownav envs do not render; use flownav.viz on rollouts")


class _Swimmers:
    """What both adapters share: the TorchRL env, the action map, numpy observations and info."""

    def __init__(self, view: str, flow, task, num_envs: int, device, env: dict, batched: bool):
        self.view = view
        self.action_shape = (num_envs, 3) if batched else (3,)
        self.nav = make_navigation_env(view, flow, task, num_envs, device=device, **env)
        self.obs_dim = observation_size(view)
        space = self.nav.action_spec.space
        self.low, self.high = space.low[0], space.high[0]
        self.seeded = False

    def seed(self, seed: int | None, np_random: np.random.Generator) -> None:
        if seed is None and not self.seeded:  # gymnasium: an unseeded first reset is seeded from entropy
            seed = int(np_random.integers(2**31))
        if seed is not None:
            self.nav.set_seed(int(seed))
        self.seeded = True

    def action(self, action) -> TensorDict:
        a = np.asarray(action, dtype=np.float32)
        if a.shape != self.action_shape:
            raise ValueError(f"action has shape {a.shape}; expected {self.action_shape} (values in [-1, 1])")
        a = torch.as_tensor(np.clip(a, -1.0, 1.0), device=self.nav.device).reshape(self.nav.num_envs, 3)
        act = self.low + (self.high - self.low) * (a + 1) / 2
        return TensorDict({"action": act}, batch_size=self.nav.batch_size, device=self.nav.device)

    def observation(self, td: TensorDictBase) -> np.ndarray:
        return td[self.view].cpu().numpy().copy()

    @staticmethod
    def info(td: TensorDictBase) -> dict[str, np.ndarray]:
        status = td["status"][:, 0].cpu().numpy()
        info = {k: td[k].cpu().numpy().copy() for k in ("position", "target", "velocity", "heading")}
        info.update(time=td["time"][:, 0].cpu().numpy().copy(), status=status, is_success=status == Status.SUCCESS)
        return info


class FlowNavEnv(gymnasium.Env):
    """One swimmer (a NavigationEnv with B = 1); see the module docstring for spaces, info and seeding.

    Args:
        view: the observation view (a key of ``flownav.envs.observations.VIEWS``).
        flow, task: a name in ``conf/flow/`` / ``conf/task/`` or a config dict the builders accept.
        device: torch device of the simulation.
        **env: overrides of ``conf/env/default.yaml`` (``time_limit=30``, ``flow_strength=[0, 0]``, ...).
    """

    metadata = {"render_modes": []}

    def __init__(
        self, view: str = DEFAULT_VIEW, flow="cylinder", task="regions", device="cpu", render_mode=None, **env
    ):
        _refuse_render(render_mode)
        self.swimmers = _Swimmers(view, flow, task, 1, device, env, batched=False)
        self.observation_space = spaces.Box(-np.inf, np.inf, (self.swimmers.obs_dim,), np.float32)
        self.action_space = spaces.Box(-1.0, 1.0, (3,), np.float32)

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        self.swimmers.seed(seed, self.np_random)
        td = self.swimmers.nav.reset()
        return self.swimmers.observation(td)[0], self._info(td)

    def step(self, action):
        nxt = self.swimmers.nav.step(self.swimmers.action(action))["next"]
        obs = self.swimmers.observation(nxt)[0]
        reward = float(nxt["reward"][0, 0])
        return obs, reward, bool(nxt["terminated"][0, 0]), bool(nxt["truncated"][0, 0]), self._info(nxt)

    def _info(self, td: TensorDictBase) -> dict:
        info = {k: v[0] for k, v in self.swimmers.info(td).items()}
        info.update(time=float(info["time"]), status=int(info["status"]), is_success=bool(info["is_success"]))
        return info


class FlowNavVectorEnv(VectorEnv):
    """B swimmers stepped together (one NavigationEnv), same-step autoreset; arguments as :class:`FlowNavEnv`.

    ``reset(options={"reset_mask": mask})`` resets only the swimmers where ``mask`` (shape ``(B,)``) is true.
    ``reset(seed=s)`` takes one integer: the B swimmers draw their episodes from one generator.
    """

    metadata = {"render_modes": [], "autoreset_mode": AutoresetMode.SAME_STEP}

    def __init__(
        self,
        num_envs: int,
        view: str = DEFAULT_VIEW,
        flow="cylinder",
        task="regions",
        device="cpu",
        render_mode=None,
        **env,
    ):
        _refuse_render(render_mode)
        self.num_envs = int(num_envs)
        self.swimmers = _Swimmers(view, flow, task, self.num_envs, device, env, batched=True)
        self.single_observation_space = spaces.Box(-np.inf, np.inf, (self.swimmers.obs_dim,), np.float32)
        self.single_action_space = spaces.Box(-1.0, 1.0, (3,), np.float32)
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self._root = None  # the TorchRL root tensordict of the current step

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        if seed is not None and not isinstance(seed, int | np.integer):
            raise ValueError(f"seed={seed!r}: FlowNavVectorEnv takes one integer seed for all {self.num_envs} swimmers")
        super().reset(seed=seed)
        self.swimmers.seed(seed, self.np_random)
        nav = self.swimmers.nav
        mask = (options or {}).get("reset_mask")
        if mask is None or self._root is None:
            self._root = nav.reset()
        else:
            mask = torch.as_tensor(np.asarray(mask, dtype=bool), device=nav.device).reshape(self.num_envs, 1)
            # TorchRL's partial reset: the last root carries the kept swimmers' entries, "_reset" says who restarts.
            self._root = nav.reset(self._root.set("_reset", mask))
        return self.swimmers.observation(self._root), self._vector_info(self._root)

    def step(self, actions):
        if self._root is None:
            raise gymnasium.error.ResetNeeded("call reset() before step()")
        td = self.swimmers.action(actions)
        stepped, self._root = self.swimmers.nav.step_and_maybe_reset(td)
        nxt = stepped["next"]
        done = nxt["done"][:, 0].cpu().numpy()
        reward = nxt["reward"][:, 0].cpu().numpy().astype(np.float64)
        terminated, truncated = nxt["terminated"][:, 0].cpu().numpy(), nxt["truncated"][:, 0].cpu().numpy()
        info = self._vector_info(self._root)
        if done.any():
            final_obs = np.full(self.num_envs, None, dtype=object)
            for i, row in zip(np.flatnonzero(done), self.swimmers.observation(nxt)[done], strict=True):
                final_obs[i] = row
            info.update(final_obs=final_obs, _final_obs=done, final_info=self._vector_info(nxt, done), _final_info=done)
        return self.swimmers.observation(self._root), reward, terminated, truncated, info

    def _vector_info(self, td: TensorDictBase, mask: np.ndarray | None = None) -> dict:
        """Gymnasium's vector info: each key's array over the swimmers and its ``_key`` mask of who has it."""
        mask = np.ones(self.num_envs, dtype=bool) if mask is None else mask
        info = self.swimmers.info(td)
        info.update({f"_{k}": mask.copy() for k in list(info)})
        return info
