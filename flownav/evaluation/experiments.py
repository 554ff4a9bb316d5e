"""The paper's experiments as data: a ``suite`` of entries, each run by the experiment kind it names.

An entry (``conf/evaluate/experiment/*.yaml``) names its ``kind``, its policies (keys of ``policies``), a
flow, a task, env overrides, an episode count, the paper's numbers (``paper``) and the report's targets
(``targets``). The kinds are the modules of ``flownav/evaluation/kinds/`` (one per kind, registered in
:mod:`flownav.evaluation.registry`); every episode they run comes from :func:`flownav.evaluation.protocol.evaluate`
through :meth:`Suite.rollout`.

A policy whose checkpoint is missing, or a flow whose dataset is missing, is skipped with an entry
that says which command produces it; the rest of the suite still runs.
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from pathlib import Path

from omegaconf import DictConfig, OmegaConf

from flownav.builders import build_flow, build_task
from flownav.checkpoint import load_policy
from flownav.errors import CheckpointError, DataError
from flownav.evaluation.kinds import kind
from flownav.evaluation.protocol import EVAL_SEED, EvalSpec, Evaluation, evaluate
from flownav.evaluation.registry import Missing
from flownav.evaluation.scripted import SCRIPTED, scripted_view
from flownav.evaluation.tables import log_line
from flownav.paths import resolve
from flownav.provenance import sha256

__all__ = ["Missing", "Suite", "plain", "run_suite"]


def plain(node):
    """A config node as plain Python containers (a non-config value as it is)."""
    return OmegaConf.to_container(node, resolve=True) if OmegaConf.is_config(node) else node


class Suite:
    """Runs suite entries, caching flows and policies across them."""

    def __init__(self, cfg: DictConfig, figures_dir: Path | None = None, log=print, provenance: dict | None = None):
        self.cfg = cfg
        self.device = str(cfg.get("device", "cpu"))
        self.seed = int(cfg.get("seed", EVAL_SEED))
        self.chunk_size = int(cfg.get("chunk_size", 10_000))
        self.max_episodes = cfg.get("max_episodes")
        self.progress = bool(cfg.get("progress", False))  # a bar over each experiment's episodes
        # evaluate.py sets figures_dir (the run directory unless shipping); a library caller's default is ./figures
        self.figures_dir = Path(figures_dir or cfg.get("figures_dir") or "figures")
        self.log = log
        self.provenance = dict(provenance or {})  # the run's commit, time, command: into an entry's own json file
        self._flows: dict[str, object] = {}
        self._policies: dict[str, tuple] = {}

    # ------------------------------------------------------------------ resources
    def episodes(self, n) -> int:
        n = int(n)
        return min(n, int(self.max_episodes)) if self.max_episodes else n

    def flow(self, flow_cfg: Mapping):
        key = OmegaConf.to_yaml(OmegaConf.create(plain(flow_cfg)))
        if key not in self._flows:
            try:
                self._flows[key] = build_flow(flow_cfg, device=self.device)
            except DataError as e:
                raise Missing(f"missing flow dataset: {e}") from e
        return self._flows[key]

    def policy(self, name: str):
        """(policy, obs view, info) of a named policy; :class:`Missing` if its checkpoint does not exist."""
        if name not in self._policies:
            entry = self.cfg.policies.get(name)
            if entry is None:
                raise KeyError(f"unknown policy {name!r}; the config's policies are {sorted(self.cfg.policies)}")
            if entry.get("scripted"):
                self._policies[name] = self._scripted(name, str(entry.scripted), plain(entry.get("settings")) or {})
                return self._policies[name]
            path = resolve(str(entry.checkpoint))
            if not path.is_file():
                raise Missing(f"missing checkpoint {entry.checkpoint}: run `{entry.command}`")
            expect = entry.get("obs")
            try:
                policy, payload = load_policy(path, expect_obs=expect, device=self.device)
            except CheckpointError as e:
                raise Missing(str(e)) from e
            info = {
                "checkpoint": str(entry.checkpoint),
                "sha256": sha256(path),
                "obs": payload["obs"],
                "role": payload["role"],
            }
            self._policies[name] = (policy, payload["obs"], info)
        return self._policies[name]

    @staticmethod
    def _scripted(name: str, kind: str, settings: dict | None = None):
        if kind not in SCRIPTED:
            raise ValueError(f"policies.{name}.scripted is {kind!r}; choose one of {sorted(SCRIPTED)}")
        try:
            policy = SCRIPTED[kind](**(settings or {}))
        except (TypeError, ValueError) as e:
            raise ValueError(f"policies.{name}.settings: {e}") from e
        view = scripted_view(policy)
        info = {"checkpoint": f"scripted:{kind}", "sha256": "-", "obs": view, "role": "reference"}
        return policy, view, info | ({"settings": settings} if settings else {})

    def episodes_of(self, spec, name: str) -> int:
        """How many episodes entry ``spec`` runs of policy ``name``: its ``episodes``, capped by its own
        ``policy_episodes[name]`` or, where it names none, by the policy's ``max_episodes`` (the oracle runs
        fewer). The cap is the entry's, so a policy's count does not depend on what else runs with it."""
        caps = spec.get("policy_episodes") or {}
        cap = caps[name] if name in caps else self.cfg.policies[name].get("max_episodes")
        return min(int(spec.episodes), int(cap)) if cap else int(spec.episodes)

    def spec(self, name: str, flow, task_cfg, env_cfg, episodes: int, seed: int | None = None) -> EvalSpec:
        """The :class:`EvalSpec` of policy ``name`` on one setting: the suite's seed (or ``seed``), its chunk size,
        ``episodes`` capped by ``max_episodes`` (an entry's count per policy: :meth:`episodes_of`)."""
        episodes = self.episodes(episodes)
        seed = self.seed if seed is None else int(seed)
        return EvalSpec(flow, build_task(task_cfg, flow), env_cfg, episodes, seed, self.chunk_size, self.device)

    def rollout(self, name: str, flow, task_cfg, env_cfg, episodes: int, seed: int | None = None, record: int = 0):
        """:func:`protocol.evaluate` of policy ``name`` on :meth:`spec`'s episodes."""
        policy, obs, _ = self.policy(name)
        spec = self.spec(name, flow, task_cfg, env_cfg, episodes, seed)
        return evaluate(policy, obs, spec, record=record, progress=self.progress)

    def measure(self, entry: str, pol: str, flow, task_cfg, env_cfg, episodes: int, label: str = "") -> Evaluation:
        """:meth:`rollout`, logged as one line of the entry's log, its summary timed in ``seconds``."""
        t0 = time.time()
        ev = self.rollout(pol, flow, task_cfg, env_cfg, episodes)
        ev.summary["seconds"] = round(time.time() - t0, 2)
        self.log(f"[{entry}] {pol}{label}: {log_line(ev.summary)}")
        return ev

    def env_cfg(self, spec) -> DictConfig:
        return OmegaConf.merge(self.cfg.env, spec.get("env") or {})

    def each_policy(self, spec, out):
        """The entry's policies that exist (recorded in ``out["policies"]``); the others are noted as missing."""
        for name in spec.policies:
            try:
                _, obs, info = self.policy(name)
            except Missing as e:
                out["missing"].append(f"{name}: {e}")
                continue
            out["policies"][name] = info
            yield name

    def sweep_figure(self, name, results, xs, xlabel, title, **kwargs) -> list:
        """Success against the swept value, one curve per policy (no figure when nothing ran)."""
        if not results:
            return []
        from flownav.viz.plots import plot_sweep

        return [plot_sweep(results, xs, self.figures_dir / f"{name}.png", xlabel=xlabel, title=title, **kwargs)]

    # ------------------------------------------------------------------ one entry
    @staticmethod
    def entry_kind(name: str, spec):
        try:
            return kind(str(spec.kind))
        except ValueError as e:
            raise ValueError(f"suite.{name}.kind: {e}") from None

    def missing(self, name: str, spec) -> dict[str, str]:
        """Each policy of entry ``name`` that cannot be loaded here, with the line that says what makes it."""
        out = {}
        for pol in dict.fromkeys(self.entry_kind(name, spec).policies(spec)):
            try:
                self.policy(pol)
            except Missing as e:
                out[pol] = str(e)
        return out

    def run(self, name: str, spec: DictConfig) -> dict:
        k = self.entry_kind(name, spec)
        t0 = time.time()
        out = {"title": str(spec.get("title", name)), "kind": k.name, "paper_ref": spec.get("paper_ref")}
        out["paper"] = plain(spec.get("paper")) or {}
        out["targets"] = plain(spec.get("targets")) or []
        # every missing checkpoint is reported, even if the flow is missing
        out["missing"] = [f"{pol}: {e}" for pol, e in self.missing(name, spec).items()]
        out["policies"] = {}
        # A cap may name a policy the entry does not run (a narrowed `suite.<name>.policies=[...]` keeps the
        # experiment's caps); it must name a policy of the config.
        for pol, n in (spec.get("policy_episodes") or {}).items():
            if pol not in self.cfg.policies:
                raise ValueError(
                    f"suite.{name}.policy_episodes.{pol}: no policy {pol!r} in the config's policies "
                    f"{sorted(self.cfg.policies)}; fix the name or define policies.{pol}"
                )
            if not isinstance(n, int) or isinstance(n, bool) or n < 1:
                raise ValueError(f"suite.{name}.policy_episodes.{pol} is {n!r}; give a whole number of episodes >= 1")
        try:
            out.update(k.run(self, name, spec, out))
        except Missing as e:  # nothing measured: the entry is skipped
            out["missing"].append(str(e))
            out["skipped"] = True
        out["missing"] = list(dict.fromkeys(out["missing"]))
        out["seconds"] = round(time.time() - t0, 2)
        return out


def run_suite(cfg: DictConfig, log=print, provenance: dict | None = None) -> dict:
    """Run every entry of ``cfg.suite`` (in order); returns ``{name: result}``. ``provenance`` (the run's commit,
    time and command) goes into every file an entry writes of its own (``json:``), as results/paper.json has it."""
    suite = Suite(cfg, log=log, provenance=provenance)
    results = {}
    for name, spec in cfg.suite.items():
        if spec is None or not spec.get("enabled", True):
            continue
        log(f"== {name}: {spec.get('title', '')}")
        results[name] = suite.run(name, spec)
        results[name]["command"] = str(spec.get("command") or f"python evaluate.py +experiment=paper_{name}")
        for m in results[name]["missing"]:
            log(f"   skipped: {m}")
    return results
