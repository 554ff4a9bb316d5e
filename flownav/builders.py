"""Build flows, tasks and environments from the ``flow``, ``task`` and ``env`` config groups.

Every value is checked here, so a bad config fails at start with a message naming the key.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

from flownav.envs.navigation import NavigationEnv
from flownav.envs.reward import RewardConfig
from flownav.envs.tasks import FamilyTask, FixedTargetTask, RegionTask, SymmetricTask
from flownav.flows.analytic import ABCFlow, UniformFlow
from flownav.flows.base import WAKE_BOUNDS, Box, FlowField
from flownav.flows.families import (
    FlowFamily,
    FourierFamily,
    MixtureFamily,
    SumFamily,
    UniformFamily,
    vortex_street_family,
    wake_family,
)
from flownav.flows.grid import load_grid_flow
from flownav.flows.transforms import ScaledFlow
from flownav.paths import DEFAULT_FLOW_DATASET, resolve


class ConfigError(ValueError):
    """A config value is wrong; the message names the key and what it accepts."""


def _box(value, key: str) -> Box:
    try:
        lo, hi = value
        box = Box(tuple(float(x) for x in lo), tuple(float(x) for x in hi))
    except (TypeError, ValueError) as e:
        raise ConfigError(f"{key} must be [[x0, y0, z0], [x1, y1, z1]] with x1 > x0 etc.; got {value} ({e})") from e
    return box


def _scale_pi(value, key: str):
    """Boxes of the ABC task are given in units of pi when ``in_pi`` is set."""
    return [[float(x) * math.pi for x in corner] for corner in value]


def _pick(cfg: Mapping, key: str, choices: Mapping):
    kind = cfg.get("type")
    if kind not in choices:
        raise ConfigError(f"{key}.type is {kind!r}; choose one of {sorted(choices)}")
    return choices[kind]


def _family_member(cfg: Mapping, key: str, bounds: Box, device) -> FlowFamily:
    """One member of a flow family (flownav/flows/families.py): its type and its constructor's arguments."""
    args = {k: v for k, v in cfg.items() if k not in ("type", "weight")}
    kind = cfg.get("type")
    if kind == "sum":
        parts = args.get("members") or {}
        return SumFamily([_family_member(m, f"{key}.members.{n}", bounds, device) for n, m in parts.items()], bounds)

    def wake(path=None, **kw):
        return wake_family(load_grid_flow(resolve(path or DEFAULT_FLOW_DATASET), device=device), **kw)

    makers = {"fourier": FourierFamily, "uniform": UniformFamily, "vortex_street": vortex_street_family, "wake": wake}
    maker = _pick(cfg, key, {**makers, "sum": None})
    try:
        return maker(bounds=bounds, **args)
    except (TypeError, ValueError) as e:
        raise ConfigError(f"{key} (type: {kind}): {e}") from e


def build_flow(cfg: Mapping, device="cpu") -> FlowField:
    def grid():
        path = cfg.get("path") or DEFAULT_FLOW_DATASET
        return load_grid_flow(resolve(path), device=device)

    def abc():
        kw = {k: float(cfg[k]) for k in ("A", "B", "C", "eps", "omega") if cfg.get(k) is not None}
        if cfg.get("bounds") is not None:
            kw["bounds"] = _box(_scale_pi(cfg["bounds"], "flow.bounds"), "flow.bounds")
        return ABCFlow(**kw)

    def uniform():
        kw = {"velocity": tuple(float(v) for v in cfg.get("velocity", (1.0, 0.0, 0.0)))}
        if cfg.get("bounds") is not None:
            kw["bounds"] = _box(cfg["bounds"], "flow.bounds")
        return UniformFlow(**kw)

    def vortex_street():
        from flownav.flows.vortex_street import VortexStreetFlow

        names = ("period", "advection", "circulation", "core_radius", "half_spacing", "spreading", "deficit")
        kw = {k: float(cfg[k]) for k in names if cfg.get(k) is not None}
        return VortexStreetFlow(**kw)

    def family():
        bounds = _box(cfg["bounds"], "flow.bounds") if cfg.get("bounds") is not None else WAKE_BOUNDS
        members = cfg.get("members") or {}
        if not members:
            raise ConfigError("flow.members must name at least one member, e.g. {fourier: {type: fourier, weight: 1}}")
        built = {name: _family_member(m, f"flow.members.{name}", bounds, device) for name, m in members.items()}
        if len(built) == 1:
            return next(iter(built.values()))
        weights = [float(members[name].get("weight", 1.0)) for name in built]
        try:
            return MixtureFamily(list(built.values()), weights, bounds)
        except ValueError as e:
            raise ConfigError(f"flow.members.*.weight: {e}") from e

    kinds = {"grid": grid, "abc": abc, "uniform": uniform, "vortex_street": vortex_street, "family": family}
    flow = _pick(cfg, "flow", kinds)()
    scale = float(cfg.get("speed_scale", 1.0))
    if scale <= 0:
        raise ConfigError(f"flow.speed_scale must be > 0, got {scale}")
    return ScaledFlow(flow, scale) if scale != 1.0 else flow


def build_task(cfg: Mapping, flow: FlowField):
    conv = (lambda v, k: _box(_scale_pi(v, k), k)) if cfg.get("in_pi") else _box

    def regions():
        return RegionTask(conv(cfg["start"], "task.start"), conv(cfg["target"], "task.target"))

    def symmetric():
        return SymmetricTask(conv(cfg["start"], "task.start"), conv(cfg["target"], "task.target"))

    def fixed_target():
        start = flow.bounds if cfg.get("start") in (None, "domain") else conv(cfg["start"], "task.start")
        target = cfg["target"]
        if len(target) != 3:
            raise ConfigError(f"task.target must be a point [x, y, z] for a fixed-target task, got {target}")
        return FixedTargetTask(target=target, start=start)

    def family():
        kw = {k: cfg[k] for k in ("distance", "swim_speed") if cfg.get(k) is not None}
        kw |= {k: float(cfg[k]) for k in ("margin", "regions_share", "full_speed_share") if cfg.get(k) is not None}
        if cfg.get("start") is not None:
            kw |= {
                "start_region": _box(cfg["start"], "task.start"),
                "target_region": _box(cfg["target"], "task.target"),
            }
        try:
            return FamilyTask(flow.bounds, **kw)
        except (TypeError, ValueError) as e:
            raise ConfigError(f"task (type: family): {e}") from e

    kinds = {"regions": regions, "symmetric": symmetric, "fixed_target": fixed_target, "family": family}
    return _pick(cfg, "task", kinds)()


def _flow_strength(value):
    """The config's shape and types; the range is NavigationEnv's to check (one place for both entry points)."""
    if value is None:
        return None
    try:
        low, high = (float(v) for v in value)
    except (TypeError, ValueError) as e:
        raise ConfigError(f"env.flow_strength must be null or [low, high], e.g. [0.0, 1.0]; got {value}") from e
    return low, high


def _fraction(value, key: str) -> float:
    try:
        return float(value or 0.0)
    except (TypeError, ValueError) as e:
        raise ConfigError(f"{key} must be a fraction in [0, 1], e.g. 0.5; got {value}") from e


def build_env(
    env_cfg: Mapping, flow: FlowField, task, views, num_envs: int | None = None, seed: int = 0, device="cpu"
) -> NavigationEnv:
    reward = env_cfg.get("reward", {}) or {}
    try:
        reward_cfg = RewardConfig(**{k: float(v) for k, v in reward.items()})
    except TypeError as e:
        raise ConfigError(f"env.reward has an unknown key ({e}); keys: {list(RewardConfig.__annotations__)}") from e
    return NavigationEnv(
        flow,
        task,
        num_envs=int(num_envs if num_envs is not None else env_cfg["num_envs"]),
        views=tuple(views),
        dt=float(env_cfg["dt"]),
        time_limit=float(env_cfg["time_limit"]),
        u_max=float(env_cfg["u_max"]),
        swim_speed_scale=float(env_cfg.get("swim_speed_scale", 1.0)),
        reward=reward_cfg,
        misalignment_deg=float(env_cfg.get("misalignment_deg", 0.0)),
        random_flow_phase=bool(env_cfg.get("random_flow_phase", True)),
        flow_strength=_flow_strength(env_cfg.get("flow_strength")),
        flow_strength_full=_fraction(env_cfg.get("flow_strength_full", 0.0), "env.flow_strength_full"),
        seed=seed,
        device=device,
    )
