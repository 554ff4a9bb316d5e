"""Evaluation throughput: wall time of 10,000 deterministic episodes (goal: <= 60 s on this 2-core CPU).

    python benchmarks/eval_throughput.py            # -> benchmarks/results/eval_throughput.json

Worst case: every episode lasts the full time limit (300 steps of dt = 0.2). A synthetic grid flow of the
CFD dataset's size (spacing 0.2 over the wake box, 40 frames) with tiny velocities keeps all 10,000
swimmers in the domain until they time out, so each step costs a full-batch flow look-up, env step and
policy call (a student-sized 256 x 256 MLP). Measured for 1 and 2 torch threads. When the real dataset
and checkpoints exist, the shipped teacher and student on the real wake are timed as well.
"""

from __future__ import annotations

import platform
import sys
import time
from pathlib import Path

import torch

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from common import machine, write_result  # noqa: E402

from flownav.agents import DeterministicPolicy  # noqa: E402
from flownav.builders import compose_config  # noqa: E402
from flownav.envs import RegionTask  # noqa: E402
from flownav.evaluation import EvalSpec, evaluate  # noqa: E402
from flownav.evaluation.scripted import ACTION_LOW, action_high  # noqa: E402
from flownav.flows.synthetic import synthetic_wake  # noqa: E402

EPISODES = 10_000
TARGET_S = 60.0


class Hover(torch.nn.Module):
    """The policy's full cost, but zero swim speed: in the near-still synthetic flow nobody leaves or arrives."""

    def __init__(self, policy):
        super().__init__()
        self.policy = policy

    def forward(self, obs):
        a = self.policy(obs)
        return torch.cat((a[:, :1] * 0, a[:, 1:]), -1)


def time_eval(policy, obs: str, flow, threads: int, episodes: int = EPISODES, chunk: int = EPISODES) -> dict:
    """The wall time of flownav.evaluation.evaluate on the training env and task, held-out episodes."""
    torch.set_num_threads(threads)
    env_cfg = compose_config().env

    evaluate(policy, obs, EvalSpec(flow, RegionTask(), env_cfg, 256, chunk_size=256))  # warm-up
    t0 = time.perf_counter()
    result = evaluate(policy, obs, EvalSpec(flow, RegionTask(), env_cfg, episodes, chunk_size=chunk))
    seconds = time.perf_counter() - t0
    ep, s = result.episodes, result.summary
    steps = float(ep.time.sum() / 0.2)
    return {
        "threads": threads,
        "episodes": episodes,
        "chunk_size": chunk,
        "seconds": round(seconds, 2),
        "episodes_per_s": round(episodes / seconds, 1),
        "swimmer_steps_per_s": round(steps / seconds),
        "mean_episode_steps": round(steps / episodes, 1),
        "success_rate": s["success_rate"],
    }


def main() -> None:
    out = {
        "goal": f"{EPISODES} episodes in <= {TARGET_S:.0f} s",
        "host": f"{platform.machine()}, {torch.get_num_threads()} default torch threads, torch {torch.__version__}",
        "runs": {},
    }
    try:
        load = Path("/proc/loadavg").read_text().split()[:3]
        out["load_average_at_start"] = [float(x) for x in load]
    except OSError:
        pass
    flow = synthetic_wake(frames=40, cells=(131, 71), span_cells=20, span=4.0, frame_dt=0.25, strength=0.002)
    student = DeterministicPolicy(6, ACTION_LOW, action_high(), hidden=(256, 256))
    teacher = DeterministicPolicy(8, ACTION_LOW, action_high(), hidden=(128, 128), n_outputs=6)
    for threads in (1, 2):
        for name, pol, obs in (("student_256x256", Hover(student), "ego"), ("teacher_128x128", Hover(teacher), "geo")):
            key = f"worst_case_{name}_threads{threads}"
            out["runs"][key] = time_eval(pol, obs, flow, threads)
            print(key, out["runs"][key], flush=True)

    data, ck = ROOT / "data" / "cylinder_re300", ROOT / "checkpoints"
    if (data / "meta.json").is_file():
        from flownav.checkpoint import load_policy
        from flownav.flows.grid import load_grid_flow

        wake = load_grid_flow(data)
        for name in ("teacher", "student"):
            path = ck / f"{name}.pt"
            if path.is_file():
                pol, payload = load_policy(path)
                key = f"real_wake_{name}_threads1"
                out["runs"][key] = time_eval(pol, payload["obs"], wake, 1)
                print(key, out["runs"][key], flush=True)
    best = min(out["runs"].values(), key=lambda r: r["seconds"])
    worst1 = out["runs"]["worst_case_student_256x256_threads1"]
    out["headline"] = (
        f"{EPISODES} episodes, all lasting the full 300 steps, student-sized policy: {worst1['seconds']:.1f} s "
        f"with 1 thread ({worst1['swimmer_steps_per_s']:,} swimmer-steps/s); goal <= {TARGET_S:.0f} s "
        f"({'met' if worst1['seconds'] <= TARGET_S else 'NOT met'}); fastest configuration: {best['seconds']:.1f} s"
    )
    out["command"] = "python benchmarks/eval_throughput.py " + " ".join(sys.argv[1:])
    out["machine"] = machine()
    write_result("eval_throughput", out)


if __name__ == "__main__":
    main()
