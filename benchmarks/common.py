"""Shared helpers of the benchmarks: machine description, the JSON result file, an env stepped in place."""

from __future__ import annotations

import json
import os
from pathlib import Path

import torch

from flownav.atomic import atomic_write_text
from flownav.provenance import provenance

RESULTS = Path(__file__).resolve().parent / "results"


def machine() -> dict:
    """The benchmark's provenance (flownav.provenance) and what its speed depends on."""
    return provenance() | {
        "cpu_count": os.cpu_count(),
        "torch_threads": torch.get_num_threads(),
        "torch": torch.__version__,
        "load_average_1min": os.getloadavg()[0],
    }


def write_result(name: str, payload: dict) -> Path:
    RESULTS.mkdir(parents=True, exist_ok=True)
    path = RESULTS / f"{name}.json"
    atomic_write_text(path, json.dumps(payload, indent=2) + "\n")
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
