"""The declared schema of every config group: each key's type and range, checked in one place.

``train.py`` and ``evaluate.py`` check the composed config against it before anything runs; the
builders check their group again when a suite entry overrides it. A wrong value fails with one line
that names the key and what it accepts (``algo.epochs must be >= 1, an integer; got 1.5``). Every
float must be finite. Checks that tie keys together (``eval_every`` a multiple of ``log_every``)
stay with the code that needs them (``flownav.algorithms.*.check_config``).

Why a declared schema and not Hydra structured configs: Hydra reports a structured-config type
error while composing, before ``main`` runs, as a multi-line message it formats itself; the keys of
``flow`` depend on its ``type``; the evaluation suite reuses the groups at other packages
(``/flow@suite.abc.flow``); and OmegaConf does not run range checks when it merges. Checking the
composed config gives every entry point the same one-line messages from one table per group.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

from flownav.errors import ConfigError

INT, FLOAT, BOOL, STR, INTS, FLOATS, BOOLS, STRS, DICTS, MAPPING, BOX, DEVICE = (
    "int",
    "float",
    "bool",
    "str",
    "ints",
    "floats",
    "bools",
    "strs",
    "dicts",
    "mapping",
    "box",
    "device",
)
LISTS = (INTS, FLOATS, BOOLS, STRS, DICTS)
BOX_SHAPE = "[[x0, y0, z0], [x1, y1, z1]] with x1 > x0 etc."


@dataclass(frozen=True)
class Key:
    """One key: its kind, an optional range (``ge``/``gt``/``le``/``lt``), choices, list size, null."""

    kind: str
    ge: float | None = None
    gt: float | None = None
    le: float | None = None
    lt: float | None = None
    choices: tuple = ()
    size: int | None = None
    null: bool = False
    required: bool = False

    def range_text(self) -> str:
        lo = ("[", self.ge) if self.ge is not None else ("(", self.gt) if self.gt is not None else None
        hi = (self.le, "]") if self.le is not None else (self.lt, ")") if self.lt is not None else None
        if lo and hi:
            return f"in {lo[0]}{lo[1]:g}, {hi[0]:g}{hi[1]}"
        if lo:
            return f"{'>=' if lo[0] == '[' else '>'} {lo[1]:g}"
        if hi:
            return f"{'<=' if hi[1] == ']' else '<'} {hi[0]:g}"
        return ""

    def type_text(self) -> str:
        text = {
            INT: "an integer",
            FLOAT: "a finite number",
            BOOL: "true or false",
            STR: "a string",
            INTS: "a non-empty list of integers",
            FLOATS: f"a list of {self.size or 'any number of'} finite numbers",
            BOOLS: f"a list of {self.size or 'any number of'} true/false values",
            STRS: "a list of strings",
            DICTS: "a list of objects",
            MAPPING: "a group of keys",
            BOX: BOX_SHAPE,
            DEVICE: "a torch device (cpu, cuda, cuda:0)",
        }[self.kind]
        return text + (" or null" if self.null else "")


def Int(ge=None, gt=None, le=None, null=False, required=False) -> Key:
    return Key(INT, ge=ge, gt=gt, le=le, null=null, required=required)


def Float(ge=None, gt=None, le=None, lt=None, null=False, required=False) -> Key:
    return Key(FLOAT, ge=ge, gt=gt, le=le, lt=lt, null=null, required=required)


def Bool() -> Key:
    return Key(BOOL)


def Str(choices=(), null=False, required=False) -> Key:
    return Key(STR, choices=tuple(choices), null=null, required=required)


def Keywords(null=False) -> Key:
    """A group of keys the schema does not list: a constructor's keywords, checked by that constructor."""
    return Key(MAPPING, null=null)


def _is_int(v) -> bool:
    return not isinstance(v, bool) and (
        isinstance(v, int) or (isinstance(v, float) and math.isfinite(v) and v.is_integer())
    )


def _is_float(v) -> bool:
    return not isinstance(v, bool) and isinstance(v, int | float) and math.isfinite(v)


def _in_range(key: Key, v) -> bool:
    return (
        (key.ge is None or v >= key.ge)
        and (key.gt is None or v > key.gt)
        and (key.le is None or v <= key.le)
        and (key.lt is None or v < key.lt)
    )


def _is_list(v) -> bool:
    return isinstance(v, Sequence) and not isinstance(v, str)


def _device_problem(v) -> str | None:
    from flownav.devices import device_problem

    return device_problem(v)


def check_value(path: str, key: Key, v, error=ConfigError) -> None:
    """Raise ``error`` (one line, naming ``path``) unless ``v`` fits ``key``."""
    if v is None:
        if key.null:
            return
        raise error(f"{path} is null; set it to {key.type_text()}")
    if key.choices and (key.kind == STR or isinstance(v, str)):
        if v not in key.choices:
            raise error(f"{path} is {v!r}; choose one of {sorted(key.choices)}")
        return
    if key.kind in LISTS:
        what = key.type_text() + (f", each {key.range_text()}" if key.range_text() else "")
    else:
        what = ", ".join(t for t in (key.range_text(), key.type_text()) if t)
    bad = f"{path} must be {what}; got {v!r}"
    if key.kind == INT:
        ok = _is_int(v) and _in_range(key, v)
    elif key.kind == FLOAT:
        ok = _is_float(v) and _in_range(key, v)
    elif key.kind == BOOL:
        ok = isinstance(v, bool)
    elif key.kind == STR:
        ok = isinstance(v, str)
    elif key.kind == INTS:
        ok = _is_list(v) and len(v) > 0 and all(_is_int(h) and _in_range(key, h) for h in v)
    elif key.kind == FLOATS:
        ok = _is_list(v) and (key.size is None or len(v) == key.size)
        ok = ok and all(_is_float(x) and _in_range(key, x) for x in v)
    elif key.kind == BOOLS:
        ok = _is_list(v) and (key.size is None or len(v) == key.size) and all(isinstance(x, bool) for x in v)
    elif key.kind == STRS:
        ok = _is_list(v) and all(isinstance(x, str) for x in v)
    elif key.kind == DICTS:
        ok = _is_list(v) and all(isinstance(x, Mapping) for x in v)
    elif key.kind == MAPPING:  # its keys are checked by the code that reads them
        ok = isinstance(v, Mapping)
    elif key.kind == BOX:
        ok = (
            _is_list(v)
            and len(v) == 2
            and all(_is_list(c) and len(c) == 3 and all(_is_float(x) for x in c) for c in v)
            and all(h > lo for lo, h in zip(v[0], v[1], strict=True))
        )
    elif key.kind == DEVICE:
        problem = _device_problem(v) if isinstance(v, str) else "is not a string"
        if problem:
            raise error(f"{path}={v} {problem}")
        ok = True
    else:  # pragma: no cover - a schema typo
        raise AssertionError(f"unknown kind {key.kind!r}")
    if not ok:
        raise error(bad)


def check_group(
    cfg: Mapping, schema: Mapping, prefix: str, closed: bool = False, error=ConfigError, join: str = "."
) -> None:
    """Check the keys of ``cfg`` that ``schema`` declares (nested dicts are sub-groups, always closed).

    ``closed``: refuse keys the schema does not declare (groups Hydra's struct mode does not guard).
    ``join``: between ``prefix`` and a key (``env.dt``; ``meta.json: dt``).
    """
    if not isinstance(cfg, Mapping):
        raise error(f"{prefix} must be a group of keys ({sorted(schema)}); got {cfg!r}")
    if closed:
        unknown = sorted(set(cfg) - set(schema))
        if unknown:
            raise error(f"{prefix} has an unknown key {unknown[0]!r}; keys: {list(schema)}")
    for name, key in schema.items():
        path = f"{prefix}{join}{name}" if prefix else name
        if name not in cfg:
            if isinstance(key, Key) and key.required:
                raise error(f"{path} is missing; set it to {key.type_text()}")
            continue
        if isinstance(key, Mapping):
            check_group(cfg[name] if cfg[name] is not None else {}, key, path, closed=True, error=error)
        else:
            check_value(path, key, cfg[name], error)


# ----------------------------------------------------------------------------- the groups
REWARD = {
    "alpha": Float(ge=0),
    "time_penalty": Float(ge=0),
    "success_bonus": Float(),
    "success_radius": Float(gt=0),
}

ENV = {
    "num_envs": Int(ge=1),
    "dt": Float(gt=0, required=True),
    "time_limit": Float(gt=0, required=True),
    "u_max": Float(gt=0, required=True),
    "swim_speed_scale": Float(gt=0),
    "misalignment_deg": Float(),
    "random_flow_phase": Bool(),
    "flow_strength": Key(FLOATS, size=2, null=True),  # its range is NavigationEnv's to check
    "flow_strength_full": Float(ge=0, le=1),
    # gradient: null (exact) by default, so runs saved before it existed resume (check_resume_settings)
    "sensor_noise": {"flow": Float(ge=0), "target": Float(ge=0), "gradient": Float(ge=0, null=True)},
    "sensor_bias": {k: Float(ge=0, null=True) for k in ("flow", "target", "gradient")}  # null: none (resumes)
    | {"frame": Str(choices=("world", "body"), null=True)},  # the flow and to-target biases' frame; null: world
    "reward": REWARD,
}

FLOW_COMMON = {
    "type": Str(required=True),
    "speed_scale": Float(gt=0),
    "periodic_axes": Key(STRS, null=True),  # e.g. [y, z]: positions wrap, the target counts at any periodic image
    "rotate_deg": Float(),  # the flow (with its domain and obstacles) turned about z, the task not
    "rotate_center": Key(FLOATS, size=2),
}
FLOWS = {
    "grid": {"path": Str(null=True)},
    "abc": {k: Float() for k in ("A", "B", "C", "eps", "omega")} | {"bounds": Key(BOX, null=True)},
    "uniform": {"velocity": Key(FLOATS, size=3), "bounds": Key(BOX, null=True)},
    # params: the flow class's keywords, checked by the class
    "zoo": {"name": Str(required=True), "params": Keywords(null=True), "bounds": Key(BOX, null=True)},
    "validation": {"name": Str(required=True), "params": Keywords(null=True), "bounds": Key(BOX, null=True)},
    # members: each a family's type and keywords, checked by its constructor (flows/families.py)
    "family": {"members": Keywords(null=True), "bounds": Key(BOX, null=True)},
    "vortex_street": {
        "period": Float(gt=0),
        "advection": Float(gt=0),
        "circulation": Float(),
        "core_radius": Float(gt=0),
        "half_spacing": Float(ge=0),
        "spreading": Float(),
        "deficit": Float(),
    },
}

TASKS = {
    "regions": {"start": Key(BOX, required=True), "target": Key(BOX, required=True)},
    "symmetric": {"start": Key(BOX, required=True), "target": Key(BOX, required=True)},
    "fixed_target": {"start": Key(BOX, choices=("domain",), null=True), "target": Key(FLOATS, size=3, required=True)},
    "family": {
        "distance": Key(FLOATS, size=2, gt=0),
        "margin": Float(ge=0),
        "regions_share": Float(ge=0, le=1),
        "posed_wake_regions_share": Float(ge=0, le=1, null=True),
        "posed_wake_any_start_share": Float(ge=0, le=1),
        "posed_wake_any_start_box": Key(BOX, null=True),
        "posed_wake_reverse_share": Float(ge=0, le=1),
        "start": Key(BOX, null=True),
        "target": Key(BOX, null=True),
        "swim_speed": Key(FLOATS, size=2, gt=0),
        "full_speed_share": Float(ge=0, le=1),
    },
    "distance": {
        "box": Key(BOX, choices=("domain",), null=True),
        "distance": Key(FLOATS, size=2, ge=0),
        "margin": Float(ge=0),
    },
}

LOGGER = {
    "progress": Bool(),
    "progress_keys": Key(STRS),
    "figure_episodes": Int(ge=0),
    "tensorboard": Bool(),
    "wandb": {
        "mode": Str(choices=("offline", "online", "disabled")),
        "project": Str(),
        "entity": Str(null=True),
        "group": Str(),
    },
}

PRIOR = Str(choices=("head_to_target",), null=True)  # the policy's output corrects head-to-target's action
PRIOR_TURN = Str(choices=("short", "left_biased"), null=True)  # how it yaws (prior.TURNS); null: left_biased
NETWORK = {"hidden": Key(INTS, ge=1), "activation": Str(choices=("tanh", "relu", "elu", "silu"))}

PPO = {
    "total_frames": Int(ge=1),
    "rollout_steps": Int(ge=1),
    "epochs": Int(ge=1),
    "minibatch_size": Int(ge=1),
    "lr": Float(gt=0),
    "anneal_lr": Bool(),
    "gamma": Float(gt=0, le=1),
    "lmbda": Float(gt=0, le=1),
    "clip_epsilon": Float(gt=0, lt=1),
    "entropy_coeff": Float(ge=0),
    "critic_coeff": Float(ge=0),
    "loss_critic_type": Str(choices=("l1", "l2", "smooth_l1")),
    "recompute_advantage": Bool(),
    "update_normalizer": Bool(),
    "normalize_advantage": Bool(),
    "max_grad_norm": Float(gt=0),
    "actor": NETWORK
    | {
        "init_scale": Float(gt=0),
        "scale_lb": Float(gt=0),
        "output_gain": Float(gt=0),
        "prior": PRIOR,
        "prior_turn": PRIOR_TURN,
    },
    "critic": NETWORK,
    "init_from": Str(null=True),
    "critic_warmup_frames": Int(ge=0, null=True),
    "anchor_coeff": Float(ge=0, null=True),
    "log_every": Int(ge=1),
    "eval_every": Int(ge=0),
    "eval_episodes": Int(ge=0),
    "target_success": Float(ge=0, le=1),
    "final_eval_episodes": Int(ge=0),
}

IMITATOR_NET = NETWORK | {"prior": PRIOR, "prior_turn": PRIOR_TURN}  # a DAgger-trained DeterministicPolicy

DAGGER = {
    "iterations": Int(ge=1),
    "num_envs": Int(ge=1),
    "steps_per_iteration": Int(ge=1),
    "beta": {"initial": Float(ge=0, le=1), "decay": Float(ge=0, le=1)},
    "buffer_capacity": Int(ge=1),
    "batch_size": Int(ge=1),
    "updates_per_iteration": Int(ge=1),
    "lr": Float(gt=0),
    "lr_final": Float(gt=0, null=True),
    "weight_decay": Float(ge=0),
    "grad_clip": Float(ge=0),
    **IMITATOR_NET,
    "scene_expert": Str(null=True),
    "scene_reverse_expert": Str(null=True),
    "scene_away_expert": Str(null=True),
    "scene_wake_expert": Str(null=True),
    "scene_posed_expert": Str(null=True),
    "scene_wake_regions_expert": Str(null=True),
    "scene_currents": Str(choices=("all", "vertical"), null=True),
    "scene_free_flows": Str(choices=("compensating", "capped"), null=True),
    "final_eval_episodes": Int(ge=0),
    "results_json": Str(null=True),
}

ORACLE_DAGGER = {
    "oracle": Str(choices=("oracle", "oracle_long")),
    "oracle_settings": {
        **{k: Int(ge=1) for k in ("candidates", "horizon", "blocks", "iterations", "elites", "replan_every")},
        "forecast": Bool(),
        "sensing_radius": Float(gt=0, null=True),
        "knows_walls": Bool(),
    },
    "iterations": Int(ge=1),
    "episodes": Int(ge=1),
    "init_from": Str(null=True),
    "beta_decay": Float(ge=0, le=1),
    "epochs": Int(ge=1),
    "batch_size": Int(ge=1),
    "lr": Float(gt=0),
    **IMITATOR_NET,
    "eval_episodes": Int(ge=0),
    "results_json": Str(null=True),
}

ALGOS = {"ppo": PPO, "dagger": DAGGER, "oracle_dagger": ORACLE_DAGGER}

RUN = {
    "seed": Int(),
    "device": Key(DEVICE),
    "threads": Int(ge=1, null=True),
}

TRAIN = RUN | {
    "name": Str(),
    "role": Str(choices=("teacher", "baseline", "student"), null=True),
    "teacher_checkpoint": Str(null=True),
    "resume": Str(null=True),
    "checkpoint_every": Int(ge=1, null=True),
    "output_checkpoint": Str(null=True),
    "ship": Bool(),
    "logger": LOGGER,
}

EVALUATE = RUN | {
    "checkpoint": Str(),
    "episodes": Int(ge=1),
    "output": Str(null=True),
    "chunk_size": Int(ge=1),
    "max_episodes": Int(ge=1, null=True),
    "results": Str(null=True),
    "report": Str(null=True),
    "figures_dir": Str(null=True),
    "ship": Bool(),
}


# ----------------------------------------------------------------------------- checks per group
def check_flow(cfg: Mapping, prefix: str = "flow") -> None:
    check_value(f"{prefix}.type", Str(choices=FLOWS), cfg.get("type") if isinstance(cfg, Mapping) else None)
    check_group(cfg, FLOW_COMMON | FLOWS[cfg["type"]], prefix, closed=True)


def check_task(cfg: Mapping, prefix: str = "task") -> None:
    check_value(f"{prefix}.type", Str(choices=TASKS), cfg.get("type") if isinstance(cfg, Mapping) else None)
    check_group(cfg, {"type": Str(), "in_pi": Bool()} | TASKS[cfg["type"]], prefix, closed=True)


def check_env(cfg: Mapping, prefix: str = "env") -> None:
    check_group(cfg, ENV, prefix, closed=True)


def check_obs(cfg: Mapping, prefix: str = "obs") -> None:
    from flownav.envs.observations import VIEWS

    check_group(cfg, {"view": Str(choices=VIEWS, required=True), "critic_view": Str(choices=VIEWS, null=True)}, prefix)


def check_algo(cfg: Mapping, prefix: str = "algo") -> None:
    check_value(f"{prefix}.name", Str(choices=ALGOS), cfg.get("name"))
    check_group(cfg, ALGOS[cfg["name"]], prefix)


def check_train(cfg: Mapping) -> None:
    """Every group of ``train.py``'s composed config."""
    check_group(cfg, TRAIN, "")
    check_algo(cfg["algo"])
    check_obs(cfg["obs"])
    check_flow(cfg["flow"])
    check_task(cfg["task"])
    check_env(cfg["env"])


def check_evaluate(cfg: Mapping) -> None:
    """The keys of ``evaluate.py``'s composed config and its flow, task and env groups."""
    from flownav.envs.observations import VIEWS

    check_group(cfg, EVALUATE | {"expect_obs": Str(choices=VIEWS, null=True)}, "")
    check_flow(cfg["flow"])
    check_task(cfg["task"])
    check_env(cfg["env"])
