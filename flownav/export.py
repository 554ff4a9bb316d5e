"""Export a policy checkpoint as a self-contained file a robot can run, with a JSON card beside it.

    python -m flownav.export checkpoint=checkpoints/student.pt format=onnx out=exports/student.onnx
    python -m flownav.export checkpoint=checkpoints/student.pt format=torchscript out=exports/student.pt

The exported model is the checkpoint's deterministic policy, whole: ``observation [batch, n] float32 ->
normaliser (the training statistics, clipped at +-10) -> MLP -> tanh -> action [batch, 3]`` in the paper's bounds
(speed in [0, u_max], turn rates in rad per time unit). The card (``<out>.json``, also embedded in the file: ONNX
metadata ``flownav_card``, TorchScript extra file ``card.json``) says what each input and output means and in
which units, which flow and task the policy was trained on, and its success numbers from ``results/paper.json``
when the suite evaluated this very file (matched by sha256), else "unknown".
"""

from __future__ import annotations

import json
import sys
import tempfile
from pathlib import Path

import torch

from flownav.atomic import atomic_write, atomic_write_text
from flownav.checkpoint import load_policy
from flownav.envs.observations import HISTORY_LEN, HISTORY_STRIDE
from flownav.errors import ConfigError, reported_as_one_line
from flownav.paths import REPO_ROOT, RESULTS_DIR, resolve
from flownav.provenance import sha256
from flownav.shipping import is_shipped

FORMATS = {"onnx": ".onnx", "torchscript": ".pt"}
ARGUMENTS = ("checkpoint", "format", "out")
INPUT_NAME, OUTPUT_NAME = "observation", "action"
PAPER_RESULTS = RESULTS_DIR / "paper.json"


USAGE = """usage: python -m flownav.export checkpoint=PATH [format=onnx|torchscript] [out=PATH]

Write the checkpoint's deterministic policy (normaliser included) as one file a robot can run, and its card
(<out>.json: the observation view, each input's meaning and units, the action bounds, the training flow and
its success numbers).

arguments (key=value):
  checkpoint  a policy checkpoint, e.g. checkpoints/student.pt (required; a relative path not found here is
              taken from the repository)
  format      onnx (default; needs the [export] extra) or torchscript
  out         the model file (default: exports/<checkpoint name>.onnx, or .pt for torchscript)

More: docs/ecosystem.md, "Exporting a policy"."""


# ---------------------------------------------------------------------------- what the numbers mean
def _vector(name: str, meaning: str, units: str, axes: str) -> list[dict]:
    return [{"name": f"{name}_{a}", "meaning": f"{meaning}, {a} component", "units": units} for a in axes]


_INERTIAL, _BODY = "xyz", ("forward", "left", "up")
_TARGET = "target position minus swimmer position"
_VELOCITY = "swimmer velocity over ground (swim + flow)"
_FLOW = "local flow velocity (velocity over ground minus own swim velocity)"
_THETA = {"name": "theta", "meaning": "heading azimuth about the inertial z axis, in [-pi, pi]", "units": "rad"}
_PSI = {"name": "psi", "meaning": "heading elevation above the x-y plane, in [-pi/2, pi/2]", "units": "rad"}
_COS_SIN_THETA = [
    {"name": "cos_theta", "meaning": "cosine of the heading azimuth theta", "units": "1"},
    {"name": "sin_theta", "meaning": "sine of the heading azimuth theta", "units": "1"},
]
_UP = [
    {"name": "sin_psi", "meaning": "sine of the heading elevation psi (from a gravity sensor)", "units": "1"},
    {"name": "cos_psi", "meaning": "cosine of the heading elevation psi", "units": "1"},
]

_SWIM_SPEED = {"name": "swim_speed", "meaning": "the swimmer's own full swim speed (its propulsion)", "units": "L/T"}


def _geo(vel_meaning: str, sincos: bool) -> list[dict]:
    heading = [*_COS_SIN_THETA, _PSI] if sincos else [_THETA, _PSI]
    vel = "velocity" if vel_meaning == _VELOCITY else "flow"
    return [
        *_vector("to_target", f"{_TARGET}, inertial frame", "L", _INERTIAL),
        *_vector(vel, f"{vel_meaning}, inertial frame", "L/T", _INERTIAL),
        *heading,
    ]


def _ego(vel_meaning: str) -> list[dict]:
    body = "body frame (forward = heading, left = horizontal to its left, up = forward x left)"
    return [
        *_vector("to_target", f"{_TARGET}, {body}", "L", _BODY),
        *_vector("velocity" if vel_meaning == _VELOCITY else "flow", f"{vel_meaning}, {body}", "L/T", _BODY),
    ]


def _memory(name: str = "flow", meaning: str = "local flow velocity", units: str = "L/T") -> list[dict]:
    """A memory's samples, newest first (the flow's, or with other arguments the to-target readings')."""
    out = []
    for k in range(HISTORY_LEN):
        when = "now" if k == 0 else f"{k * HISTORY_STRIDE} steps ago"
        out += _vector(f"{name}_{k}", f"{meaning} {when}, in the current body frame", units, _BODY)
    return out


def _gradient() -> list[dict]:
    return [
        {
            "name": f"dflow_{i}_d{j}",
            "meaning": f"change of the local flow's {i} component along the body's {j} axis (body frame): a forward "
            f"difference over 0.05 L, exact in training (no sensor noise)",
            "units": "1/T",
        }
        for i in _BODY
        for j in _BODY
    ]


VIEW_INPUTS = {
    "geo": lambda: _geo(_VELOCITY, sincos=False),
    "geo_flow": lambda: _geo(_FLOW, sincos=False),
    "geo_sincos": lambda: _geo(_VELOCITY, sincos=True),
    "geo_flow_sincos": lambda: _geo(_FLOW, sincos=True),
    "ego": lambda: _ego(_VELOCITY),
    "ego_flow": lambda: _ego(_FLOW),
    "ego_up": lambda: [*_ego(_VELOCITY), *_UP],
    "ego_mem": lambda: [*_ego(_VELOCITY), *_UP, *_memory()],
    "ego_mem_speed": lambda: [*_ego(_VELOCITY), *_UP, *_memory(), _SWIM_SPEED],
    "ego_mem_grad": lambda: [*_ego(_VELOCITY), *_UP, *_memory(), *_gradient()],
    "ego_mem_grad_track": lambda: [*VIEW_INPUTS["ego_mem_grad"](), *_memory("to_target", f"{_TARGET} as read", "L")],
}


def observation_inputs(view: str) -> list[dict]:
    """One entry per number of the view, in order: name, meaning, units (L, T: the flow's length and time units)."""
    if view not in VIEW_INPUTS:
        raise ConfigError(f"view {view!r} is not an actor view; an exported policy reads one of {sorted(VIEW_INPUTS)}")
    return [{"index": i, **entry} for i, entry in enumerate(VIEW_INPUTS[view]())]


def action_outputs(low, high) -> list[dict]:
    meanings = [
        ("speed", "swim speed along the heading (the swimmer gets it times env.swim_speed_scale)", "L/T"),
        ("dtheta", "turn rate of the azimuth theta, about the inertial vertical", "rad/T"),
        ("dpsi", "turn rate of the elevation psi, towards the vertical", "rad/T"),
    ]
    return [
        {"index": i, "name": n, "meaning": m, "units": u, "low": lo, "high": hi}
        for i, ((n, m, u), lo, hi) in enumerate(zip(meanings, low, high, strict=True))
    ]


def flow_units(flow_cfg: dict) -> dict:
    """L, T of the training flow: a grid dataset's meta.json ``units``; analytic flows are nondimensional."""
    if flow_cfg.get("type") == "grid":
        meta = resolve(flow_cfg.get("path") or "data/cylinder_re300") / "meta.json"
        if meta.is_file():
            units = json.loads(meta.read_text()).get("units")
            if units:
                return {"L": units.get("length"), "L/T": units.get("velocity"), "T": units.get("time")}
        return {"L": "unknown (dataset meta.json not found)", "L/T": "unknown", "T": "unknown"}
    if not flow_cfg:
        return {"L": "unknown (the checkpoint records no training flow)", "L/T": "unknown", "T": "unknown"}
    kind = flow_cfg.get("type")
    return {"L": f"nondimensional length of the {kind} flow", "L/T": "its nondimensional velocity", "T": "L / (L/T)"}


def suite_results(digest: str, path: Path = PAPER_RESULTS) -> list[dict] | str:
    """Success numbers of this checkpoint (sha256 prefix ``digest``) in the evaluation suite's results."""
    if not path.is_file():
        return f"unknown: no {path.name} (python evaluate.py +experiment=paper writes it)"
    experiments = json.loads(path.read_text()).get("experiments", {})
    found = []
    for key, ex in experiments.items():
        for name, info in (ex.get("policies") or {}).items():
            res = (ex.get("results") or {}).get(name)
            if info.get("sha256") != digest or not isinstance(res, dict) or "success_rate" not in res:
                continue
            found.append(
                {
                    "experiment": key,
                    "title": ex.get("title"),
                    "policy": name,
                    "episodes": res.get("episodes"),
                    "success_rate": res["success_rate"],
                    "success_ci95": res.get("success_ci95"),
                    "mean_success_time": res.get("mean_success_time"),
                    "source": f"results/{path.name}",
                    "command": ex.get("command"),
                    "provenance": ex.get("provenance"),
                }
            )
    return found or f"unknown: results/{path.name} has no evaluation of this file (sha256 {digest})"


def make_card(checkpoint: Path, payload: dict, policy, fmt: str, out: Path) -> dict:
    meta = payload.get("meta") or {}
    train_cfg = meta.get("config") or {}
    flow_cfg = train_cfg.get("flow") or {}
    cfg = policy.config
    return {
        "format": fmt,
        "file": out.name,
        "input": {"name": INPUT_NAME, "shape": ["batch", cfg["obs_dim"]], "dtype": "float32"},
        "output": {"name": OUTPUT_NAME, "shape": ["batch", len(cfg["action_low"])], "dtype": "float32"},
        "observation": {
            "view": payload["obs"],
            "inputs": observation_inputs(payload["obs"]),
            "normaliser": "included: (x - mean) / sqrt(var + 1e-6) with the training statistics, clipped at +-10",
        },
        "action": {
            "outputs": action_outputs(cfg["action_low"], cfg["action_high"]),
            "deterministic": "low + (high - low) (tanh(mlp) + 1) / 2: the mean action, no sampling",
        },
        "units": flow_units(flow_cfg),
        "policy": {
            "checkpoint": str(
                checkpoint.relative_to(REPO_ROOT) if checkpoint.is_relative_to(REPO_ROOT) else checkpoint
            ),
            "checkpoint_sha256": sha256(checkpoint),
            "role": payload.get("role"),
            "hidden": cfg["hidden"],
            "activation": cfg["activation"],
        },
        "training": {
            "flow": flow_cfg or "unknown",
            "task": train_cfg.get("task") or "unknown",
            "env": train_cfg.get("env") or "unknown",
            "frames": meta.get("frames", "unknown"),
            "final_log_metrics": {k: v for k, v in (meta.get("metrics") or {}).items() if "success" in k} or "unknown",
        },
        "success": suite_results(sha256(checkpoint)),
    }


# ---------------------------------------------------------------------------- writing the files
def _write_onnx(policy, example: torch.Tensor, out: Path, card_json: str) -> None:
    try:
        import onnx
        import onnxscript  # noqa: F401 - torch.onnx's exporter needs it
    except ImportError as e:
        raise ConfigError(f"format=onnx needs {e.name} (the export extra): pip install -e '.[export]'") from e

    with tempfile.TemporaryDirectory() as tmp:
        raw = Path(tmp) / "policy.onnx"
        torch.onnx.export(
            policy,
            (example,),
            raw,
            input_names=[INPUT_NAME],
            output_names=[OUTPUT_NAME],
            dynamic_shapes=({0: torch.export.Dim("batch")},),
            external_data=False,  # one file: the weights inside
            verbose=False,
        )
        model = onnx.load(raw)
    model.metadata_props.add(key="flownav_card", value=card_json)
    atomic_write(out, lambda f: f.write(model.SerializeToString()))


def _write_torchscript(policy, example: torch.Tensor, out: Path, card_json: str) -> None:
    scripted = torch.jit.trace(policy, example)  # an MLP without branches: tracing records all of it
    atomic_write(out, lambda f: torch.jit.save(scripted, f, _extra_files={"card.json": card_json}))


def export_policy(checkpoint, fmt: str = "onnx", out=None) -> tuple[Path, Path]:
    """Write the exported policy and its card; returns (model path, card path)."""
    if fmt not in FORMATS:
        raise ConfigError(f"format={fmt}: choose one of {', '.join(FORMATS)}")
    checkpoint = resolve(checkpoint)  # like evaluate.py: relative to the repository when not found here
    policy, payload = load_policy(checkpoint)
    out = Path(out) if out else Path("exports") / f"{checkpoint.stem}{FORMATS[fmt]}"
    card_path = out.with_name(out.name + ".json")
    # an export is never a shipped file (flownav/shipping.py); checked where it is written, relative to here
    if is_shipped(out.absolute()) or is_shipped(card_path.absolute()):
        raise ConfigError(
            f"out={out} is in a shipped place (checkpoints/, results/, data/ or REPORT.md); write the export "
            "elsewhere, e.g. the default exports/"
        )
    card = make_card(checkpoint, payload, policy, fmt, out)
    card_json = json.dumps(card, indent=2)
    example = torch.zeros(2, policy.config["obs_dim"])
    (_write_onnx if fmt == "onnx" else _write_torchscript)(policy, example, out, card_json)
    atomic_write_text(card_path, card_json + "\n")
    return out, card_path


def parse_arguments(argv) -> dict:
    args = {"format": "onnx", "out": None}
    for arg in argv:
        key, sep, value = arg.partition("=")
        if not sep or key not in ARGUMENTS:
            raise ConfigError(f"unknown argument {arg!r}; use key=value with keys {', '.join(ARGUMENTS)}")
        args[key] = value
    if not args.get("checkpoint"):
        raise ConfigError("checkpoint= is required, e.g. checkpoint=checkpoints/student.pt")
    return args


def main(argv=None) -> int:
    """Bad input (an argument, a checkpoint): ``error: <one line>`` on stderr, exit status 2, as train.py and
    evaluate.py (FLOWNAV_DEBUG=1 shows the traceback)."""
    argv = sys.argv[1:] if argv is None else list(argv)
    if {"-h", "--help", "help"} & set(argv):
        print(USAGE)
        return 0
    with reported_as_one_line():
        args = parse_arguments(argv)
        torch.set_num_threads(1)
        model, card = export_policy(args["checkpoint"], args["format"], args["out"])
    print(f"wrote {model} and its card {card}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
