"""Shared helpers of the benchmarks: machine description, the JSON result file, an env stepped in place."""

from __future__ import annotations

import datetime as _dt
import json
import os
import platform
import subprocess
from pathlib import Path

import torch

RESULTS = Path(__file__).resolve().parent / "results"


def machine() -> dict:
    try:
        commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True).stdout.strip()
    except OSError:
        commit = ""
    return {
        "date_utc": _dt.datetime.now(_dt.UTC).strftime("%Y-%m-%d %H:%M"),
        "commit": commit,
        "cpu_count": os.cpu_count(),
        "torch_threads": torch.get_num_threads(),
        "torch": torch.__version__,
        "python": platform.python_version(),
        "load_average_1min": os.getloadavg()[0],
    }


def write_result(name: str, payload: dict) -> Path:
    RESULTS.mkdir(parents=True, exist_ok=True)
    path = RESULTS / f"{name}.json"
    path.write_text(json.dumps(payload, indent=2) + "\n")
    print(json.dumps({"headline": payload.get("headline")}, indent=2))
    print(f"wrote {path}")
    return path


def env_stepper(env, warmup: int = 3):
    """A function that steps ``env`` once (one fixed random action, auto-reset), after ``warmup`` steps."""
    state = {"td": env.reset()}
    action = env.action_spec.rand()

    def step():
        td = state["td"]
        td["action"] = action
        _, state["td"] = env.step_and_maybe_reset(td)

    for _ in range(warmup):
        step()
    return step
