"""Build flows, tasks and environments from the ``flow``, ``task`` and ``env`` config groups.

Each group is checked against its schema (:mod:`flownav.schema`) first, so a bad config fails at
start with one line naming the key.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

from flownav import schema
from flownav.envs.navigation import NavigationEnv
from flownav.envs.reward import RewardConfig
from flownav.envs.tasks import DistanceTask, FamilyTask, FixedTargetTask, RegionTask, SymmetricTask
from flownav.errors import ConfigError
from flownav.flows.analytic import ABCFlow, UniformFlow
from flownav.flows.base import WAKE_BOUNDS, Box, FlowField, axis_indices, make_periodic
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
from flownav.flows.transforms import RotatedFlow, ScaledFlow
from flownav.paths import DEFAULT_FLOW_DATASET, REPO_ROOT, resolve

__all__ = ["build_env", "build_flow", "build_task", "compose_config"]


def _box(value) -> Box:
    """A box the schema has checked: [[x0, y0, z0], [x1, y1, z1]]."""
    lo, hi = value
    return Box(tuple(float(x) for x in lo), tuple(float(x) for x in hi))


def _scale_pi(value):
    """Boxes of the ABC task are given in units of pi when ``in_pi`` is set."""
    return [[float(x) * math.pi for x in corner] for corner in value]


def _family_member(cfg: Mapping, key: str, bounds: Box, device, periodic: tuple[int, ...] = ()) -> FlowFamily:
    """One member of a flow family (flownav/flows/families.py): its type and its constructor's arguments;
    ``periodic``: the family's periodic axes, on which random Fourier modes take whole periods of the box."""
    args = {k: v for k, v in cfg.items() if k not in ("type", "weight")}
    kind = cfg.get("type")
    if kind == "sum":
        if extra := sorted(set(args) - {"members"}):
            raise ConfigError(f"{key} (type: sum) has an unknown key {extra[0]!r}; a sum takes only members")
        parts = {f"{key}.members.{n}": m for n, m in (args.get("members") or {}).items()}
        if weighted := [k for k, m in parts.items() if "weight" in m]:  # every part is added to every swimmer's flow
            raise ConfigError(f"{weighted[0]}.weight: a part of a sum has no weight (every part is added); drop it")
        return SumFamily([_family_member(m, k, bounds, device, periodic) for k, m in parts.items()], bounds)
    if kind == "fourier" and periodic:
        args["periodic_axes"] = periodic

    def wake(path=None, **kw):
        return wake_family(load_grid_flow(resolve(path or DEFAULT_FLOW_DATASET), device=device), **kw)

    makers = {"fourier": FourierFamily, "uniform": UniformFamily, "vortex_street": vortex_street_family, "wake": wake}
    if kind not in makers:
        raise ConfigError(f"{key}.type is {kind!r}; choose one of {sorted([*makers, 'sum'])}")
    maker = makers[kind]
    try:
        return maker(bounds=bounds, **args)
    except (TypeError, ValueError) as e:
        raise ConfigError(f"{key} (type: {kind}): {e}") from e


def build_flow(cfg: Mapping, device="cpu") -> FlowField:
    schema.check_flow(cfg)

    def grid():
        path = cfg.get("path") or DEFAULT_FLOW_DATASET
        return load_grid_flow(resolve(path), device=device)

    def abc():
        kw = {k: float(cfg[k]) for k in ("A", "B", "C", "eps", "omega") if cfg.get(k) is not None}
        if cfg.get("bounds") is not None:
            kw["bounds"] = _box(_scale_pi(cfg["bounds"]))
        return ABCFlow(**kw)

    def uniform():
        kw = {"velocity": tuple(float(v) for v in cfg.get("velocity", (1.0, 0.0, 0.0)))}
        if cfg.get("bounds") is not None:
            kw["bounds"] = _box(cfg["bounds"])
        return UniformFlow(**kw)

    def vortex_street():
        from flownav.flows.vortex_street import VortexStreetFlow

        names = ("period", "advection", "circulation", "core_radius", "half_spacing", "spreading", "deficit")
        kw = {k: float(cfg[k]) for k in names if cfg.get(k) is not None}
        return VortexStreetFlow(**kw)

    def named(registry: dict, what: str):
        """A flow of the zoo or of the validation set: its class by ``name``, the class's keywords in ``params``."""
        if cfg["name"] not in registry:
            raise ConfigError(f"flow.name is {cfg['name']!r}; the {what} flows are {sorted(registry)}")
        kw = dict(cfg.get("params") or {})
        if cfg.get("bounds") is not None:
            kw["bounds"] = _box(cfg["bounds"])
        try:
            return registry[cfg["name"]](**kw)
        except TypeError as e:
            raise ConfigError(f"flow.params: {e}") from e

    def zoo():
        from flownav.flows.zoo import ZOO

        return named(ZOO, "zoo's")

    def validation():
        from flownav.flows.validation import VALIDATION

        return named(VALIDATION, "validation set's")

    def family():
        bounds = _box(cfg["bounds"]) if cfg.get("bounds") is not None else WAKE_BOUNDS
        members = cfg.get("members") or {}
        if not members:
            raise ConfigError("flow.members must name at least one member, e.g. {fourier: {type: fourier, weight: 1}}")
        try:
            periodic = axis_indices(cfg.get("periodic_axes") or ())
        except ValueError as e:
            raise ConfigError(str(e)) from e
        built = {
            name: _family_member(m, f"flow.members.{name}", bounds, device, periodic) for name, m in members.items()
        }
        if len(built) == 1:
            return next(iter(built.values()))
        weights = [float(members[name].get("weight", 1.0)) for name in built]
        try:
            return MixtureFamily(list(built.values()), weights, bounds)
        except ValueError as e:
            raise ConfigError(f"flow.members.*.weight: {e}") from e

    kinds = {
        "grid": grid,
        "abc": abc,
        "uniform": uniform,
        "vortex_street": vortex_street,
        "zoo": zoo,
        "validation": validation,
        "family": family,
    }
    flow = kinds[cfg["type"]]()
    if cfg.get("periodic_axes"):
        try:
            make_periodic(flow, list(cfg["periodic_axes"]), device=device)
        except ValueError as e:
            raise ConfigError(str(e)) from e
    scale = float(cfg.get("speed_scale", 1.0))
    flow = ScaledFlow(flow, scale) if scale != 1.0 else flow
    if cfg.get("rotate_deg"):  # the flow alone (domain and obstacles with it), not the task: unlike misalignment
        center = tuple(float(c) for c in cfg.get("rotate_center", (0.0, 0.0)))
        flow = RotatedFlow(flow, float(cfg["rotate_deg"]), center)
    return flow


def build_task(cfg: Mapping, flow: FlowField):
    schema.check_task(cfg)
    conv = (lambda v: _box(_scale_pi(v))) if cfg.get("in_pi") else _box

    def regions():
        return RegionTask(conv(cfg["start"]), conv(cfg["target"]))

    def symmetric():
        return SymmetricTask(conv(cfg["start"]), conv(cfg["target"]))

    def fixed_target():
        start = flow.bounds if cfg.get("start") in (None, "domain") else conv(cfg["start"])
        return FixedTargetTask(target=[float(x) for x in cfg["target"]], start=start)

    def distance():
        box = flow.bounds if cfg.get("box") in (None, "domain") else conv(cfg["box"])
        margin = float(cfg.get("margin", 0.0))
        if margin:
            box = Box(tuple(x + margin for x in box.lo), tuple(x - margin for x in box.hi))
        try:
            return DistanceTask(box, tuple(cfg.get("distance", (8.0, 12.0))))
        except ValueError as e:
            raise ConfigError(str(e)) from e

    def family():
        kw = {k: cfg[k] for k in ("distance", "swim_speed") if cfg.get(k) is not None}
        shares = (
            "margin",
            "regions_share",
            "full_speed_share",
            "posed_wake_regions_share",
            "posed_wake_any_start_share",
            "posed_wake_reverse_share",
        )
        kw |= {k: float(cfg[k]) for k in shares if cfg.get(k) is not None}
        if cfg.get("posed_wake_any_start_box") is not None:
            kw["posed_wake_any_start_box"] = _box(cfg["posed_wake_any_start_box"])
        if cfg.get("start") is not None:
            kw |= {
                "start_region": _box(cfg["start"]),
                "target_region": _box(cfg["target"]),
            }
        try:
            return FamilyTask(flow.bounds, **kw)
        except (TypeError, ValueError) as e:
            raise ConfigError(f"task (type: family): {e}") from e

    kinds = {
        "regions": regions,
        "symmetric": symmetric,
        "fixed_target": fixed_target,
        "distance": distance,
        "family": family,
    }

    return kinds[cfg["type"]]()


def build_env(
    env_cfg: Mapping, flow: FlowField, task, views, num_envs: int | None = None, seed: int = 0, device="cpu"
) -> NavigationEnv:
    schema.check_env(env_cfg)
    reward = env_cfg.get("reward", {}) or {}
    strength = env_cfg.get("flow_strength")
    noise, bias = env_cfg.get("sensor_noise") or {}, env_cfg.get("sensor_bias") or {}
    try:
        return NavigationEnv(
            flow,
            task,
            num_envs=int(num_envs if num_envs is not None else env_cfg["num_envs"]),
            views=tuple(views),
            dt=float(env_cfg["dt"]),
            time_limit=float(env_cfg["time_limit"]),
            u_max=float(env_cfg["u_max"]),
            swim_speed_scale=float(env_cfg.get("swim_speed_scale", 1.0)),
            reward=RewardConfig(**{k: float(v) for k, v in reward.items()}),
            misalignment_deg=float(env_cfg.get("misalignment_deg", 0.0)),
            random_flow_phase=bool(env_cfg.get("random_flow_phase", True)),
            flow_strength=None if strength is None else tuple(float(v) for v in strength),
            flow_strength_full=float(env_cfg.get("flow_strength_full") or 0.0),
            sensor_noise=tuple(float(noise.get(key) or 0.0) for key in ("flow", "target", "gradient")),
            sensor_bias=tuple(float(bias.get(key) or 0.0) for key in ("flow", "target", "gradient")),
            sensor_bias_frame=bias.get("frame") or "world",
            seed=seed,
            device=device,
        )
    except ValueError as e:  # a range that ties env keys together (NavigationEnv, RewardConfig check it)
        raise ConfigError(f"env: {e}") from e


def compose_config(overrides=(), app: str = "train"):
    """An app's config with Hydra ``overrides``, composed outside a Hydra app: train.py's (``conf/config.yaml``) or,
    with ``app="evaluate"``, evaluate.py's (``conf/evaluate/config.yaml``)."""
    from hydra import compose, initialize_config_dir  # Hydra only for callers that compose

    config_dir = {"train": REPO_ROOT / "conf", "evaluate": REPO_ROOT / "conf" / "evaluate"}[app]
    with initialize_config_dir(config_dir=str(config_dir), version_base="1.3"):
        return compose("config", overrides=list(overrides))
