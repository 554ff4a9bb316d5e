"""Held-out success of trained checkpoints, and shipping the best seed.

    # success on 10,000 held-out episodes of each run's training task, one entry per checkpoint
    python -m flownav.evaluation.selection --name teacher --out results/teacher.json \\
        multirun/teacher/<date>/seed*/checkpoints/last.pt
    # the same, and ship the best of them (by this held-out success) to checkpoints/, atomically: only
    # finished runs of the experiment's full budget, scored on the full --episodes (flownav/shipping.py)
    python -m flownav.evaluation.selection --name teacher --out results/teacher.json \\
        --ship checkpoints/teacher.pt multirun/teacher/<date>/seed*/checkpoints/last.pt

Each checkpoint is evaluated by :func:`flownav.evaluation.protocol.evaluate` on the flow, task and env
groups of its own training run (``--override``: ``env=<config>`` replaces the run's group, ``env.<key>=<value>``
changes one key of it), on the held-out seed ``EVAL_SEED``: the
same episodes ``evaluate.py`` and the suite measure.
Where its experiment names checks a shipped policy must pass (``ship_requires`` in
``conf/experiment/<name>.yaml``, e.g. still water and currents for the generalist student), each is measured
the same way with its overrides, and ``--ship`` takes the best of the seeds that pass them all.
"""

from __future__ import annotations

import argparse
import json
import math
import shlex
import sys
from pathlib import Path

import torch

from flownav.atomic import atomic_write_text
from flownav.errors import ConfigError
from flownav.evaluation.protocol import EVAL_SEED, EvalSpec, evaluate
from flownav.provenance import provenance

EPISODES = 10_000  # held-out episodes per checkpoint; shipping needs at least these
PROG = "python -m flownav.evaluation.selection"
EVAL_GROUPS = ("flow", "task", "env")  # what an evaluation reads of a training run's config


def training_spec(payload: dict, episodes: int, overrides=(), chunk_size: int = 10_000, seed: int = EVAL_SEED):
    """The :class:`EvalSpec` of a checkpoint's training flow, task and env. ``overrides`` are Hydra overrides of
    train.py's config: a group's choice (``env=abc_periodic``) replaces the run's group with that config (keys of
    that group then change the chosen config), a key (``env.sensor_bias.flow=0.1``) changes that key of the run's
    own group and keeps the rest of it (``~key`` deletes it); the group's schema checks the result."""
    from hydra.core.override_parser.overrides_parser import OverridesParser
    from hydra.errors import HydraException
    from omegaconf import OmegaConf, open_dict
    from omegaconf.errors import OmegaConfBaseException

    from flownav.builders import build_flow, build_task, compose_config

    train_cfg = payload.get("meta", {}).get("config", {})
    try:
        parsed = OverridesParser.create().parse_overrides(list(overrides))
        own = [g for g in EVAL_GROUPS if g in train_cfg and all(o.key_or_group != g for o in parsed)]
        on_own = [o for o in parsed if o.key_or_group.split(".")[0] in own]  # a key of the run's own group
        cfg = compose_config([o.input_line for o in parsed if o not in on_own])
        with open_dict(cfg):
            for group in own:
                keys = [o for o in on_own if o.key_or_group.startswith(f"{group}.")]
                cfg[group] = _with_overridden_keys(OmegaConf.create(train_cfg[group]), cfg[group], keys, group)
    except (HydraException, OmegaConfBaseException, TypeError, ValueError) as e:  # Hydra's messages span lines
        raise ConfigError(f"--override {' '.join(overrides)}: {' '.join(str(e).split())}") from e
    flow = build_flow(cfg.flow)
    return EvalSpec(flow, build_task(cfg.task, flow), cfg.env, episodes, seed=seed, chunk_size=chunk_size)


def _with_overridden_keys(own, defaults, overrides, group: str):
    """The run's ``own`` group with each overridden key set (or deleted by ``~``); a parent the run holds as null
    or lacks (an older run) comes first from ``defaults``, train.py's default of that group."""
    from omegaconf import DictConfig, OmegaConf

    for o in overrides:
        parts = o.key_or_group[len(group) + 1 :].split(".")
        for depth in range(1, len(parts)):
            path = ".".join(parts[:depth])
            node = OmegaConf.select(own, path)
            if node is not None and not isinstance(node, DictConfig):
                raise ValueError(f"{group}.{path} is {node!r}, not a group of keys")
            if node is None:
                OmegaConf.update(own, path, OmegaConf.select(defaults, path) or {}, merge=False)
        parent = OmegaConf.select(own, ".".join(parts[:-1])) if len(parts) > 1 else own
        if o.is_delete():
            parent.pop(parts[-1], None)
        elif o.is_add() and parts[-1] in parent:  # as Hydra: + adds a key, ++ adds or sets one
            raise ValueError(f"{o.key_or_group} is already set; use {o.key_or_group}=... or ++{o.key_or_group}=...")
        else:  # a group of keys merges into the one there, as in Hydra
            OmegaConf.update(parent, parts[-1], o.value(), merge=True)
    return own


def evaluate_checkpoint(path, episodes: int = EPISODES, overrides=(), chunk_size: int = 10_000) -> dict:
    """The protocol's summary of one checkpoint on its training task, with where it came from and its
    experiment's ``ship_requires`` checks (``requirements``)."""
    from flownav.checkpoint import load_policy

    policy, payload = load_policy(path)
    obs = payload["obs"]
    summary = evaluate(policy, obs, training_spec(payload, episodes, overrides, chunk_size)).summary
    meta = payload.get("meta", {})
    checks = requirement_checks(policy, payload, episodes, overrides, chunk_size)
    return summary | {
        "checkpoint": str(path),
        "obs": obs,
        "role": payload["role"],
        "frames": meta.get("frames"),
        "experiment": meta.get("config", {}).get("name"),
        "requirements": checks,
    }


def requirement_checks(policy, payload: dict, episodes: int = EPISODES, overrides=(), chunk_size: int = 10_000) -> dict:
    """The held-out success of a loaded checkpoint (``load_policy``) in each check its experiment requires before
    shipping (``ship_requires`` of conf/experiment/<name>.yaml; each check's overrides after ``overrides``)."""
    from flownav.shipping import experiment_requirements

    name = str(payload.get("meta", {}).get("config", {}).get("name"))
    checks = {}
    for key, req in experiment_requirements(name).items():
        spec = training_spec(payload, episodes, [*overrides, *req["overrides"]], chunk_size)
        rate = evaluate(policy, payload["obs"], spec).summary["success_rate"]
        checks[key] = {
            "overrides": list(req["overrides"]),
            "min_success": float(req["min_success"]),
            "success_rate": rate,
        }
    return checks


def _mean_std(xs):
    xs = [x for x in xs if x is not None and not math.isnan(x)]
    if not xs:
        return None, None
    m = sum(xs) / len(xs)
    return m, (sum((x - m) ** 2 for x in xs) / len(xs)) ** 0.5


def select(args) -> dict:
    """Evaluate ``args.checkpoints``, write ``args.out``, and with ``args.ship`` copy the best one there."""
    from flownav.checkpoint import load_checkpoint, ship_checkpoint
    from flownav.shipping import failed_requirements, is_shipped, require_shippable

    shipped_out = is_shipped(Path(args.out).absolute())  # where it is written, relative to here
    if args.ship or shipped_out:  # refused before the (long) evaluation
        if args.episodes < EPISODES:
            raise ConfigError(
                f"--episodes {args.episodes} is below the {EPISODES} a shipped result needs; drop --ship "
                "(and write --out outside results/) for a try"
            )
        for p in args.checkpoints:
            require_shippable(load_checkpoint(p), p)
    torch.set_num_threads(args.threads)
    runs = [evaluate_checkpoint(p, args.episodes, args.override, args.chunk) for p in args.checkpoints]
    print_runs(runs)
    m, s = _mean_std([r["success_rate"] for r in runs])
    mt, _ = _mean_std([r["mean_success_time"] for r in runs])
    out = {"name": args.name} | provenance(f"{PROG} " + " ".join(shlex.quote(a) for a in sys.argv[1:]))
    out |= {
        "episodes_per_checkpoint": args.episodes,
        "eval_seed": EVAL_SEED,
        "success_rate_mean": m,
        "success_rate_std": s,
        "mean_success_time_mean": mt,
        "runs": runs,
    }
    if args.ship:  # the rule for every shipped policy: the best seed by held-out success of those that pass
        passing = [r for r in runs if not failed_requirements(r["requirements"])]  # their experiment's checks
        if not passing:
            if not shipped_out:
                atomic_write_text(args.out, json.dumps(out, indent=2))
            failed = "; ".join(f"{r['checkpoint']}: {', '.join(failed_requirements(r['requirements']))}" for r in runs)
            raise ConfigError(f"shipping refused: no checkpoint passes its experiment's ship_requires ({failed})")
        best = max(passing, key=lambda r: r["success_rate"])
        ship_checkpoint(best["checkpoint"], args.ship)
        out["shipped"] = {"checkpoint": best["checkpoint"], "to": args.ship, "success_rate": best["success_rate"]}
        print(f"shipped {best['checkpoint']} ({best['success_rate']:.4f}) -> {args.ship}")
    atomic_write_text(args.out, json.dumps(out, indent=2))
    print(json.dumps({k: v for k, v in out.items() if k != "runs"}, indent=2))
    return out


def print_runs(runs) -> None:
    """Each checkpoint's held-out success and checks, printed before any shipping decision (a refused ship keeps
    them on screen: it writes no shipped results file)."""
    for r in runs:
        print(f"{r['checkpoint']}: success {r['success_rate']:.4f}, mean success time {r['mean_success_time']}")
        for key, c in r["requirements"].items():
            print(f"  {key}: {c['success_rate']:.4f} (at least {c['min_success']})")


def main(argv=None):
    p = argparse.ArgumentParser(prog=PROG, description=__doc__.split("\n")[0])
    p.add_argument("checkpoints", nargs="+")
    p.add_argument("--name", required=True)
    p.add_argument("--out", required=True)
    p.add_argument("--episodes", type=int, default=EPISODES)
    p.add_argument("--chunk", type=int, default=10_000, help="episodes stepped together")
    p.add_argument(
        "--override",
        action="append",
        default=[],
        help="Hydra override: flow=vortex_street takes that config, env.time_limit=100 one key of the run's env",
    )
    p.add_argument("--threads", type=int, default=2)
    p.add_argument(
        "--ship",
        default=None,
        help="copy the best checkpoint (held-out success) of those that pass their experiment's checks here",
    )
    args = p.parse_args(argv)
    from flownav.errors import reported_as_one_line

    with reported_as_one_line():  # a bad argument: one line, exit status 2
        select(args)


if __name__ == "__main__":
    main()
