"""Swimmer-steps per second of the env on each flow family against the plain CFD wake, side by side,
and the generalist's training cost (wall time of finished runs).

Run: ``python benchmarks/family_throughput.py [--threads 1] [--batch 4096] [--seconds 4]``. Writes
``benchmarks/results/family_throughput.json``. ``python benchmarks/family_throughput.py --cost
teacher=<run dir> --cost student=<run dir> ...`` writes the training runs' wall times (their
``final_metrics.json``, and each one's against the first's) to ``benchmarks/results/generalist_cost.json``
(``--cost-file NAME``: NAME.json) instead; ``--pipeline generalist_student`` writes what training that student
from nothing takes, every network of its teacher included (one row per network, its scene roles listed), from the
checkpoints' recorded wall times (``--override KEY=VALUE``: the experiment's config changed, e.g.
``output_checkpoint=<run>/checkpoints/last.pt`` for a student that is not shipped).

Every case steps ``NavigationEnv.step_and_maybe_reset`` with random actions (resets included) on the flow
config ``conf/flow/<name>.yaml`` and the task the generalist trains on (``task=family``; the wake alone: the
paper's regions; the periodic family: the ABC task it is used with; the students' and the away expert's families:
their experiment's),
with the teacher's view (``geo_sincos``), with the generalist teacher's views (``geo_priv`` + ``geo_priv_critic``:
4 look-ups per step instead of 1), with the wider ``geo_priv_around`` (12 more points per step) and with what a
generalist student's DAgger env computes (``ego_mem_grad`` + ``geo_priv_scene``: 3 more points for the body-axis
gradient; and with ``ego_mem`` instead, to price them). The machine is
shared, so the cases take turns window by window and each keeps its best window; ratios are against ``cylinder``
with ``geo_sincos`` measured in the same rounds.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import env_stepper, machine, write_result  # noqa: E402

from flownav.builders import build_env, build_flow, build_task, compose_config  # noqa: E402

FLOWS = (
    "cylinder",
    "family_current",
    "family_fourier",
    "family_wake",
    "family_vortex_street",
    "family_mix",
    "family_mix_turned",
    "family_wake_posed",
    "family_fourier_periodic",
)
# The task each flow is stepped with: the generalist's family task unless the flow has its own; the flows an
# experiment trains on with that experiment's task (the students' paper's regions in the posed wake and other starts;
# the away expert's starts anywhere in the posed wake).
TASKS = {"cylinder": "regions", "family_fourier_periodic": "abc"}
EXPERIMENTS = {"family_mix_turned": "generalist_student", "family_wake_posed": "generalist_away_expert"}
VIEWS = {
    "teacher view (geo_sincos)": ("geo_sincos",),
    "privileged views (geo_priv + critic)": ("geo_priv", "geo_priv_critic"),
    "wider privileged view (geo_priv_around + critic)": ("geo_priv_around", "geo_priv_critic"),
    # what a generalist student's DAgger env computes: its ego view and the scene-routed teacher's view
    "student's DAgger views (ego_mem_grad + geo_priv_scene)": ("ego_mem_grad", "geo_priv_scene"),
    "the same with ego_mem (no body-axis gradient)": ("ego_mem", "geo_priv_scene"),
}


def make_stepper(flow_name: str, views, batch: int):
    if flow_name in EXPERIMENTS:
        cfg = compose_config([f"+experiment={EXPERIMENTS[flow_name]}", f"flow={flow_name}", "env=default"])
    else:
        cfg = compose_config(
            [f"flow={flow_name}", f"task={TASKS.get(flow_name, 'family')}", "env=default"], app="train"
        )
    flow = build_flow(cfg.flow)
    task = build_task(cfg.task, flow)
    env = build_env(cfg.env, flow, task, views, num_envs=batch, seed=0)
    return env_stepper(env)


def window_rate(step, batch: int, seconds: float) -> float:
    calls, start = 0, time.perf_counter()
    while time.perf_counter() - start < seconds or calls < 3:
        step()
        calls += 1
    return batch * calls / (time.perf_counter() - start)


def run_cost(spec: str) -> dict:
    """``name=<run dir>``: the wall time and frames a finished training run recorded."""
    name, _, path = spec.partition("=")
    final = json.loads((Path(path) / "final_metrics.json").read_text())
    row = {"run": name, "run_dir": path, "wall_time_min": final["wall_time_s"] / 60}
    for key in ("frames", "iterations", "eval/success_rate", "eval/student_success_rate"):
        if final.get(key) is not None:
            row[key] = final[key]
    return row


def pipeline_cost(experiment: str, overrides: list[str] | tuple = ()) -> dict:
    """What training a student from nothing takes: its own run and the run of every network its teacher is made of
    (``teacher_checkpoint`` and the scene experts ``algo.scene_*expert`` of ``conf/experiment/<name>.yaml``, with
    ``overrides``: e.g. ``output_checkpoint=<run>/checkpoints/last.pt`` for a student that is not shipped), one run
    each, as each checkpoint recorded it (wall time, threads; a DAgger run's before its final evaluation). A network
    that labels several scenes trained once: one row, its roles listed; the student's row comes last. The routed
    teacher's scripted rules (``scene_currents``, ``scene_free_flows``) train nothing."""
    from flownav.builders import compose_config
    from flownav.checkpoint import load_checkpoint
    from flownav.paths import resolve

    cfg = compose_config([f"+experiment={experiment}", *overrides])
    parts = {"teacher_checkpoint": cfg.teacher_checkpoint}
    parts |= {k: v for k, v in cfg.algo.items() if k.startswith("scene_") and k.endswith("expert") and v}
    networks: dict[Path, tuple[str, list[str]]] = {}  # one entry per file, however it is spelled
    for role, path in parts.items():
        networks.setdefault(resolve(str(path)).resolve(), (str(path), []))[1].append(role)
    student = resolve(str(cfg.output_checkpoint)).resolve()
    if student in networks:
        raise ValueError(f"output_checkpoint {cfg.output_checkpoint} is a network of the teacher: pass the student's")
    networks[student] = (str(cfg.output_checkpoint), ["student"])
    rows = []
    for file, (path, roles) in networks.items():
        payload = load_checkpoint(file)
        meta, state = payload.get("meta") or {}, payload.get("train_state") or {}
        rows.append(
            {
                "roles": roles,
                "checkpoint": path,
                "experiment": (meta.get("config") or {}).get("name"),
                "wall_time_min": state["wall_time"] / 60,
                "threads": (meta.get("config") or {}).get("threads"),
                "frames": meta.get("frames"),
            }
        )
    teachers = sum(r["wall_time_min"] for r in rows[:-1])
    return {
        "what": f"training cost of {experiment} from nothing: every network of its teacher and its own run, one run "
        "each, as the checkpoints recorded it (train_state.wall_time; each ran on this machine beside what else ran "
        "then)",
        "overrides": list(overrides),
        "results": rows,
        "teacher_networks_min": teachers,
        "total_min": teachers + rows[-1]["wall_time_min"],
        "targets_min": {"teacher": 60, "student": 20},
    }


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--batch", type=int, default=4096, help="swimmers (the generalist teacher's env.num_envs)")
    parser.add_argument("--seconds", type=float, default=4.0, help="time per case, split in --rounds windows")
    parser.add_argument("--rounds", type=int, default=4)
    parser.add_argument("--flows", nargs="+", default=list(FLOWS))
    parser.add_argument("--cost", action="append", default=[], help="name=<run dir> of a finished training run")
    parser.add_argument("--cost-file", default="generalist_cost", help="benchmarks/results/<this>.json for --cost")
    parser.add_argument("--pipeline", help="an experiment (generalist_student): its whole training cost, from the "
                        "checkpoints it names, to benchmarks/results/<experiment>_pipeline_cost.json")  # fmt: skip
    parser.add_argument("--override", action="append", default=[], help="with --pipeline: a Hydra override of the "
                        "experiment, e.g. algo.scene_away_expert=<run>/checkpoints/last.pt")  # fmt: skip
    args = parser.parse_args()
    if args.pipeline:
        payload = pipeline_cost(args.pipeline, args.override)
        payload |= {"command": "python benchmarks/family_throughput.py " + " ".join(sys.argv[1:]), "machine": machine()}
        payload["headline"] = {k: payload[k] for k in ("teacher_networks_min", "total_min")}
        write_result(f"{args.pipeline}_pipeline_cost", payload)
        return
    if args.cost:
        payload = {
            "what": "wall time of the generalist's training runs (final_metrics.json of each run directory)",
            "command": "python benchmarks/family_throughput.py " + " ".join(sys.argv[1:]),
            "machine": machine(),
            "results": [run_cost(spec) for spec in args.cost],
            "targets_min": {"teacher": 60, "student": 20},
        }
        first = payload["results"][0]["wall_time_min"]
        for row in payload["results"]:  # runs trained side by side compare as ratios
            row["wall_time_vs_first"] = row["wall_time_min"] / first
        payload["headline"] = payload["results"][0]
        write_result(args.cost_file, payload)
        return
    torch.set_num_threads(args.threads)
    cases = {(f, v): make_stepper(f, views, args.batch) for f in args.flows for v, views in VIEWS.items()}
    best = dict.fromkeys(cases, 0.0)
    for _ in range(args.rounds):  # side by side: every case gets a window in every round
        for key, step in cases.items():
            best[key] = max(best[key], window_rate(step, args.batch, args.seconds / args.rounds))
    plain = best.get(("cylinder", next(iter(VIEWS))))
    rows = []
    for (flow, view), rate in best.items():
        row = {"flow": flow, "views": view, "swimmer_steps_per_s": rate}
        if plain:
            row["ratio_vs_plain_wake"] = rate / plain
        rows.append(row)
        print(f"{flow:>22} {view:>38}: {rate:>10,.0f} swimmer-steps/s" + (f" ({rate / plain:.2f}x)" if plain else ""))
    payload = {
        "what": "swimmer-steps/s of NavigationEnv.step_and_maybe_reset on each flow family vs the plain wake "
        "(cylinder, regions task, geo_sincos), cases interleaved window by window, best window each",
        "command": "python benchmarks/family_throughput.py " + " ".join(sys.argv[1:]),
        "batch": args.batch,
        "machine": machine(),
        "results": rows,
    }
    mix = next((r for r in rows if r["flow"] == "family_mix" and "priv" in r["views"]), None)
    payload["headline"] = mix
    write_result("family_throughput", payload)


if __name__ == "__main__":
    main()
