"""The paper's experiments as data: a ``suite`` of entries, each run by one function of its ``kind``.

An entry (``conf/evaluate/experiment/paper_*.yaml``) names its policies (keys of ``policies``), a
flow, a task, env overrides, an episode count and the paper's numbers. Kinds:

* ``success``       success table of each policy (training flow, ABC zero-shot, SI 1);
* ``extended``      fixed target, starts anywhere: success maps over subregions (Fig. 4, SI 2);
* ``misalignment``  the scene rotated about z by each angle (Fig. 5e);
* ``ratio_sweep``   U_max / V_max ablation by scaling the flow speed (Fig. 6c);
* ``time_limit``    success against the episode's time limit, from one run at the longest (ours);
* ``figures``       trajectories, velocity traces and a movie (Figs. 3, 5, 6);
* ``loss_curves``   DAgger loss of every student run found, mean +- std over seeds (Fig. 2c);
* ``zoo``           held-out flows against head-to-target and the oracle (generalization.py).

A policy whose checkpoint is missing, or a flow whose dataset is missing, is skipped with an entry
that says which command produces it; the rest of the suite still runs.
"""

from __future__ import annotations

import hashlib
import json
import time
from collections.abc import Mapping
from pathlib import Path

import torch
from omegaconf import DictConfig, OmegaConf

from flownav.builders import build_env, build_flow, build_task
from flownav.checkpoint import CheckpointError, load_policy
from flownav.evaluation.metrics import subregion_counts, summarize, truncate_at
from flownav.evaluation.rollout import run_episodes
from flownav.evaluation.scripted import SCRIPTED
from flownav.flows.grid import GridFlowError
from flownav.paths import resolve


class Missing(Exception):
    """Something an experiment needs does not exist yet; the message names the command that makes it."""


def _plain(node):
    return OmegaConf.to_container(node, resolve=True) if OmegaConf.is_config(node) else node


def file_digest(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()[:12]


class Suite:
    """Runs suite entries, caching flows and policies across them."""

    def __init__(self, cfg: DictConfig, figures_dir: Path | None = None, log=print):
        self.cfg = cfg
        self.device = str(cfg.get("device", "cpu"))
        self.seed = int(cfg.get("seed", 0))
        self.chunk_size = int(cfg.get("chunk_size", 10_000))
        self.max_episodes = cfg.get("max_episodes")
        self.progress = bool(cfg.get("progress", False))  # a bar over each experiment's episodes
        # evaluate.py sets figures_dir (the run directory unless shipping); a library caller's default is ./figures
        self.figures_dir = Path(figures_dir or cfg.get("figures_dir") or "figures")
        self.log = log
        self._flows: dict[str, object] = {}
        self._policies: dict[str, tuple] = {}

    # ------------------------------------------------------------------ resources
    def episodes(self, n) -> int:
        n = int(n)
        return min(n, int(self.max_episodes)) if self.max_episodes else n

    def flow(self, flow_cfg: Mapping):
        key = OmegaConf.to_yaml(OmegaConf.create(_plain(flow_cfg)))
        if key not in self._flows:
            try:
                self._flows[key] = build_flow(flow_cfg, device=self.device)
            except GridFlowError as e:
                raise Missing(f"missing flow dataset: {e}") from e
        return self._flows[key]

    def policy(self, name: str):
        """(policy, obs view, info) of a named policy; :class:`Missing` if its checkpoint does not exist."""
        if name not in self._policies:
            entry = self.cfg.policies.get(name)
            if entry is None:
                raise KeyError(f"unknown policy {name!r}; the config's policies are {sorted(self.cfg.policies)}")
            if entry.get("scripted"):
                self._policies[name] = self._scripted(name, str(entry.scripted), _plain(entry.get("settings")) or {})
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
                "sha256": file_digest(path),
                "obs": payload["obs"],
                "role": payload["role"],
            }
            self._policies[name] = (policy, payload["obs"], info)
        return self._policies[name]

    @staticmethod
    def _scripted(name: str, kind: str, settings: dict | None = None):
        if kind not in SCRIPTED:
            raise ValueError(f"policies.{name}.scripted is {kind!r}; choose one of {sorted(SCRIPTED)}")
        info = {"checkpoint": f"scripted:{kind}", "sha256": "-", "obs": "geo", "role": "reference"}
        try:
            policy = SCRIPTED[kind](**(settings or {}))
        except (TypeError, ValueError) as e:
            raise ValueError(f"policies.{name}.settings: {e}") from e
        return policy, "geo", info | ({"settings": settings} if settings else {})

    def make_env_factory(self, flow, task_cfg, env_cfg, views, seed: int):
        task = build_task(task_cfg, flow)

        def make_env(n: int, chunk: int):
            return build_env(env_cfg, flow, task, views, num_envs=n, seed=seed + 1_000_003 * chunk, device=self.device)

        return make_env

    def rollout(self, name: str, flow, task_cfg, env_cfg, episodes: int, seed: int | None = None, record: int = 0):
        policy, obs, _ = self.policy(name)
        make_env = self.make_env_factory(flow, task_cfg, env_cfg, [obs], self.seed if seed is None else seed)
        episodes = self.episodes(episodes)
        cap = self.cfg.policies[name].get("max_episodes")  # an expensive reference (the oracle) runs fewer
        episodes = min(episodes, int(cap)) if cap else episodes
        return run_episodes(policy, obs, make_env, episodes, self.chunk_size, record=record, progress=self.progress)

    def env_cfg(self, spec) -> DictConfig:
        return OmegaConf.merge(self.cfg.env, spec.get("env") or {})

    # ------------------------------------------------------------------ kinds
    def run(self, name: str, spec: DictConfig) -> dict:
        kind = spec.kind
        fn = getattr(self, f"_run_{kind}", None)
        if fn is None:
            raise ValueError(f"suite.{name}.kind is {kind!r}; choose one of {sorted(KINDS)}")
        t0 = time.time()
        out = {"title": str(spec.get("title", name)), "kind": kind, "paper_ref": spec.get("paper_ref")}
        out["paper"] = _plain(spec.get("paper")) or {}
        out["missing"] = []
        out["policies"] = {}
        for pol in _policy_names(spec):  # report every missing checkpoint, even if the flow is missing too
            try:
                self.policy(pol)
            except Missing as e:
                out["missing"].append(f"{pol}: {e}")
        try:
            out.update(fn(name, spec, out))
        except Missing as e:
            out["missing"].append(str(e))
        out["missing"] = list(dict.fromkeys(out["missing"]))
        out["seconds"] = round(time.time() - t0, 2)
        return out

    def _each_policy(self, spec, out):
        for name in spec.policies:
            try:
                _, obs, info = self.policy(name)
            except Missing as e:
                out["missing"].append(f"{name}: {e}")
                continue
            out["policies"][name] = info
            yield name

    def _run_success(self, name, spec, out) -> dict:
        flow = self.flow(spec.flow)
        env_cfg = self.env_cfg(spec)
        results = {}
        for pol in self._each_policy(spec, out):
            t0 = time.time()
            ep = self.rollout(pol, flow, spec.task, env_cfg, spec.episodes)
            results[pol] = summarize(ep.status, ep.time) | {"seconds": round(time.time() - t0, 2)}
            self.log(f"[{name}] {pol}: {_fmt(results[pol])}")
        return {"results": results, "flow_max_speed": float(flow.max_speed)}

    def _run_extended(self, name, spec, out) -> dict:
        flow = self.flow(spec.flow)
        env_cfg = self.env_cfg(spec)
        bins = [int(b) for b in spec.get("bins", (10, 10, 10))]
        results, maps, figures = {}, {}, []
        for pol in self._each_policy(spec, out):
            t0 = time.time()
            ep = self.rollout(pol, flow, spec.task, env_cfg, spec.episodes)
            counts, wins = subregion_counts(ep.start, ep.success, flow.bounds, bins)
            results[pol] = summarize(ep.status, ep.time) | {"seconds": round(time.time() - t0, 2)}
            maps[pol] = {"episodes": counts.tolist(), "successes": wins.tolist()}
            self.log(f"[{name}] {pol}: {_fmt(results[pol])}")
        if maps:
            from flownav.viz.maps import plot_success_maps

            figures = plot_success_maps(
                maps, flow, list(spec.task.target), self.figures_dir / f"{name}_success_map", title=out["title"]
            )
        return {
            "results": results,
            "maps": maps,
            "bins": bins,
            "bounds": [flow.bounds.lo, flow.bounds.hi],
            "figures": figures,
        }

    def _run_misalignment(self, name, spec, out) -> dict:
        flow = self.flow(spec.flow)
        angles = [float(a) for a in spec.angles]
        results: dict[str, dict] = {}
        for pol in self._each_policy(spec, out):
            results[pol] = {}
            for angle in angles:
                env_cfg = OmegaConf.merge(self.env_cfg(spec), {"misalignment_deg": angle})
                ep = self.rollout(pol, flow, spec.task, env_cfg, spec.episodes)
                results[pol][_angle_key(angle)] = summarize(ep.status, ep.time)
                self.log(f"[{name}] {pol} {angle:g} deg: {_fmt(results[pol][_angle_key(angle)])}")
        figures = self._sweep_figure(name, results, angles, "misalignment angle (deg)", out["title"])
        return {"angles": angles, "results": results, "figures": figures}

    def _sweep_figure(self, name, results, xs, xlabel, title, **kwargs) -> list:
        """Success against the swept value, one curve per policy (no figure when nothing ran)."""
        if not results:
            return []
        from flownav.viz.plots import plot_sweep

        return [plot_sweep(results, xs, self.figures_dir / f"{name}.png", xlabel=xlabel, title=title, **kwargs)]

    def _run_ratio_sweep(self, name, spec, out) -> dict:
        """Success against U_swim,max / V_flow,max, reached by scaling the flow's speed (as the paper does)."""
        base_cfg = OmegaConf.merge(spec.flow, {"speed_scale": 1.0})
        base = self.flow(base_cfg)
        env_cfg = self.env_cfg(spec)
        swim_max = float(env_cfg.u_max) * float(env_cfg.get("swim_speed_scale", 1.0))
        ratios = [float(r) for r in spec.ratios]
        scales = [swim_max / (r * base.max_speed) for r in ratios]
        results: dict[str, dict] = {}
        for pol in self._each_policy(spec, out):
            results[pol] = {}
            for ratio, scale in zip(ratios, scales, strict=True):
                flow = self.flow(OmegaConf.merge(base_cfg, {"speed_scale": scale}))
                ep = self.rollout(pol, flow, spec.task, env_cfg, spec.episodes)
                results[pol][_ratio_key(ratio)] = summarize(ep.status, ep.time) | {"flow_speed_scale": scale}
                self.log(f"[{name}] {pol} ratio {ratio:.3f}: {_fmt(results[pol][_ratio_key(ratio)])}")
        figures = self._sweep_figure(name, results, ratios, "U_swim,max / V_flow,max", out["title"], keyfn=_ratio_key)
        return {
            "ratios": ratios,
            "flow_speed_scales": scales,
            "base_max_speed": float(base.max_speed),
            "swim_max_speed": swim_max,
            "results": results,
            "figures": figures,
        }

    def _run_time_limit(self, name, spec, out) -> dict:
        """Success against the time limit. The paper does not give its limit, and a deterministic episode
        is the same up to any limit, so one run at the longest limit answers every shorter one."""
        flow = self.flow(spec.flow)
        limits = sorted(float(t) for t in spec.limits)
        env_cfg = OmegaConf.merge(self.env_cfg(spec), {"time_limit": limits[-1]})
        results: dict[str, dict] = {}
        for pol in self._each_policy(spec, out):
            ep = self.rollout(pol, flow, spec.task, env_cfg, spec.episodes)
            results[pol] = {}
            for limit in limits:
                status = truncate_at(ep.status, ep.time, limit, float(env_cfg.dt))
                results[pol][_angle_key(limit)] = summarize(status, ep.time)
                self.log(f"[{name}] {pol} limit {limit:g}: {_fmt(results[pol][_angle_key(limit)])}")
        figures = self._sweep_figure(name, results, limits, "time limit (time units D/U)", out["title"])
        return {"limits": limits, "results": results, "figures": figures}

    def _run_figures(self, name, spec, out) -> dict:
        from flownav.viz import trajectories as tv

        figures = []
        seed = int(spec.get("seed", self.seed))
        notes: list[str] = []
        # Fig. 3: the three policies from one start to one target in the training flow.
        wake = spec.wake
        try:
            flow = self.flow(wake.flow)
        except Missing as e:
            out["missing"].append(str(e))
            flow = None
        if flow is not None:
            env_cfg = self.env_cfg(wake)
            # Same candidate episodes for every policy; show the first that the preferred policies all solve.
            n = int(wake.get("candidates", 32))
            cands = {}
            for pol in self._each_policy(wake, out):
                cands[pol] = self.rollout(pol, flow, wake.task, env_cfg, n, seed=seed, record=n).trajectories
            i = _pick_episode(cands, list(wake.get("prefer_success", ["teacher", "student"])))
            runs = {pol: _slice_traj(tr, i) for pol, tr in cands.items()}
            if runs:
                notes.append(f"wake figures show candidate episode {i} of {n} (seed {seed})")
                figures.append(
                    tv.plot_trajectories_3d(
                        runs,
                        flow,
                        self.figures_dir / f"{name}_wake_3d.png",
                        title="Training flow: one episode of each policy",
                    )
                )
                figures.append(tv.plot_velocity_traces(runs, self.figures_dir / f"{name}_velocity_traces.png"))
                movie_pol = str(wake.get("movie_policy", "student"))
                if movie_pol in runs and spec.get("movie", True):
                    figures.append(
                        tv.make_movie(
                            runs[movie_pol],
                            flow,
                            self.figures_dir / f"{name}_movie.mp4",
                            title=f"{movie_pol} in the cylinder wake",
                            frames=int(spec.get("movie_frames", 60)),
                        )
                    )
            # Fig. 5a-d: teacher and student in misaligned wakes.
            mis = spec.get("misaligned")
            if mis is not None:
                runs = {}
                for pol in self._each_policy(mis, out):
                    for angle in mis.angles:
                        env_cfg = OmegaConf.merge(self.env_cfg(wake), {"misalignment_deg": float(angle)})
                        ep = self.rollout(
                            pol,
                            flow,
                            wake.task,
                            env_cfg,
                            int(mis.get("episodes", 4)),
                            seed=seed,
                            record=int(mis.get("episodes", 4)),
                        )
                        runs[(pol, float(angle))] = ep.trajectories
                if runs:
                    figures.append(tv.plot_misaligned(runs, flow, self.figures_dir / f"{name}_misaligned.png"))
        abc = spec.get("abc")
        if abc is not None:
            try:
                aflow = self.flow(abc.flow)
            except Missing as e:
                out["missing"].append(str(e))
                aflow = None
            if aflow is not None:
                runs = {}
                n = int(abc.get("episodes", 5))
                for pol in self._each_policy(abc, out):
                    runs[pol] = self.rollout(
                        pol, aflow, abc.task, self.env_cfg(abc), n, seed=seed, record=n
                    ).trajectories
                if runs:
                    figures.append(tv.plot_abc(runs, aflow, self.figures_dir / f"{name}_abc.png"))
        return {"figures": [str(f) for f in figures], "notes": notes}

    def _run_zoo(self, name, spec, out) -> dict:
        from flownav.evaluation.generalization import run_zoo

        return run_zoo(self, name, spec, out)

    def _run_loss_curves(self, name, spec, out) -> dict:
        from flownav.viz.plots import collect_loss_runs, plot_loss_curves

        runs = collect_loss_runs([resolve(str(g)) for g in spec.run_globs], key=str(spec.get("key", "train/loss")))
        if not runs:
            raise Missing(f"no DAgger runs found ({list(spec.run_globs)}): run `{spec.command}`")
        fig, stats = plot_loss_curves(runs, self.figures_dir / f"{name}.png", key=str(spec.get("key", "train/loss")))
        if spec.get("json"):
            path = resolve(str(spec.json))
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_text(json.dumps(stats | {"files": sorted(runs)}, indent=1))
        return {"runs": sorted(runs), "curve": stats, "figures": [str(fig)]}


def _pick_episode(runs: dict, prefer: list[str]) -> int:
    """First episode that all preferred policies solve; else the first the last preferred one solves; else 0."""
    from flownav.envs.navigation import Status

    wins = {p: runs[p]["status"] == Status.SUCCESS for p in prefer if p in runs}
    if not wins:
        return 0
    options = [torch.stack(list(wins.values())).all(0)] + [wins[p] for p in reversed(list(wins))]
    for ok in options:
        if bool(ok.any()):
            return int(ok.nonzero()[0, 0])
    return 0


def _slice_traj(traj: dict, i: int) -> dict:
    return {k: (v if k == "time" else v[i : i + 1]) for k, v in traj.items()}


def _policy_names(spec) -> list[str]:
    names = list(spec.get("policies") or [])
    for sub in ("wake", "misaligned", "abc"):
        node = spec.get(sub)
        if isinstance(node, Mapping) or OmegaConf.is_dict(node):
            names += list(node.get("policies") or [])
    return list(dict.fromkeys(names))


KINDS = ("success", "extended", "misalignment", "ratio_sweep", "time_limit", "figures", "loss_curves", "zoo")


def _angle_key(a: float) -> str:
    return f"{a:g}"


def _ratio_key(r: float) -> str:
    return f"{r:.3f}"


def _fmt(s: dict) -> str:
    lo, hi = s["success_ci95"]
    t = s["mean_success_time"]
    f = s["failures"]
    return (
        f"success {100 * s['success_rate']:.2f}% [{100 * lo:.2f}, {100 * hi:.2f}] of {s['episodes']}, time {t:.2f}"
        if t is not None
        else f"success 0 of {s['episodes']}"
    ) + (f", left {f['left_domain']['count']}, hit {f['hit_obstacle']['count']}, timeout {f['timeout']['count']}")


def run_suite(cfg: DictConfig, log=print) -> dict:
    """Run every entry of ``cfg.suite`` (in order); returns ``{name: result}``."""
    suite = Suite(cfg, log=log)
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
