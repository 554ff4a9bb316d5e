"""Try every class of bad input docs/guarantees.md names through the entry points a user types, and count the clear
errors.

    python scripts/bad_input_census.py              # every case, a table and "N cases tried, M give a one-line error"
    python scripts/bad_input_census.py -k export    # only the cases whose id contains "export"

Each case runs its entry point (``train.py``, ``evaluate.py``, ``python -m flownav.cfd``, ``python -m
flownav.export``) in a subprocess from the repository root, with its run directory in a temporary directory.
A case *gives a one-line error* when the exit status is not 0, stderr holds no Python traceback, and stderr's
last line is ``error: <message>`` holding the case's expected words (the key or file it must name). The files
under checkpoints/, results/, data/ and REPORT.md are hashed before and after: no case may change them.
``tests/test_bad_input.py`` runs one case of each entry point from :data:`CASES` and compares every message
in-process; this script is the full census (one subprocess a case, a few minutes on 2 cores).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # this checkout's flownav, whose entry points the cases run

from flownav.atomic import atomic_write_text  # noqa: E402
from flownav.provenance import tree_digest  # noqa: E402
from flownav.shipping import SHIPPED  # noqa: E402

TRAIN = ["train.py", "+experiment=teacher", "logger=csv", "logger.progress=false", "threads=1"]
STUDENT = ["train.py", "+experiment=student", "logger=csv", "logger.progress=false", "threads=1"]
EVALUATE = ["evaluate.py", "episodes=4", "progress=false"]
CFD = ["-m", "flownav.cfd", "--threads", "1", "generate"]
EXPORT = ["-m", "flownav.export"]
# A lattice just big enough for GenerateConfig.check (the tests' tiny wake).
TINY_CFD = "--re 100 --cells-per-d 4 --u-lattice 0.15 --x-range -5 26 --y-half 7.5 --span 2".split()
TINY_CFD += "--warmup 12 --record 14 --frame-dt 0.45 --out-spacing 0.5".split()

# (id, argv after the python executable, words the error line must contain). {name} is a file of make_files().
CASES = [
    # non-finite settings are refused up front, naming the key
    ("train_reward_alpha_nan", [*TRAIN, "env.reward.alpha=nan"], "env.reward.alpha"),
    ("train_success_bonus_inf", [*TRAIN, "env.reward.success_bonus=inf"], "env.reward.success_bonus"),
    ("dagger_grad_clip_nan", [*STUDENT, "algo.grad_clip=nan"], "algo.grad_clip"),
    ("train_lr_inf", [*TRAIN, "algo.lr=inf"], "algo.lr"),
    # a malicious pickle behind every loader
    ("evaluate_evil_checkpoint", [*EVALUATE, "checkpoint={evil}"], "refused to load"),
    ("dagger_evil_teacher", [*STUDENT, "teacher_checkpoint={evil}"], "refused to load"),
    ("train_evil_init_from", [*TRAIN, "algo.init_from={evil}"], "refused to load"),
    ("train_evil_resume", [*TRAIN, "resume={evil_run}"], "refused to load"),
    ("dagger_evil_resume", [*STUDENT, "resume={evil_run}"], "refused to load"),
    ("cfd_evil_state", [*CFD, *TINY_CFD, "--run-dir", "{evil_cfd}"], "refused to load"),
    ("export_evil_checkpoint", [*EXPORT, "checkpoint={evil}", "out={tmp}/e.onnx"], "refused to load"),
    # resume= takes a run directory only
    ("resume_shipped_policy", [*TRAIN, "resume=checkpoints/teacher.pt"], "is not a run directory"),
    ("resume_missing", [*TRAIN, "resume={tmp}/no_such_run"], "no such run directory"),
    ("resume_other_view", [*TRAIN, "obs=ego", "resume={good_run}"], "resume with the same obs"),
    # wrong types, silent coercions, zero / infinite values, devices, checkpoints, metadata
    ("train_total_frames_abc", [*TRAIN, "algo.total_frames=abc"], "algo.total_frames"),
    ("train_epochs_fraction", [*TRAIN, "algo.epochs=1.5"], "algo.epochs"),
    ("train_entropy_nan", [*TRAIN, "algo.entropy_coeff=nan"], "algo.entropy_coeff"),
    ("train_num_envs_zero", [*TRAIN, "env.num_envs=0"], "env.num_envs"),
    ("train_time_limit_inf", [*TRAIN, "env.time_limit=inf"], "env.time_limit"),
    ("train_log_every_zero", [*TRAIN, "algo.log_every=0"], "algo.log_every"),
    ("train_misalignment_nan", [*TRAIN, "env.misalignment_deg=nan"], "env.misalignment_deg"),
    ("train_task_not_fitting_flow", [*TRAIN, "flow=abc"], "task= does not fit flow="),
    ("train_cuda", [*TRAIN, "device=cuda"], "device=cuda"),
    ("evaluate_cuda", [*EVALUATE, "device=cuda"], "device=cuda"),
    ("train_hidden_mismatch", [*TRAIN, "algo.init_from={small}"], "hidden=[16]"),
    ("evaluate_missing_policy_key", [*EVALUATE, "checkpoint={nopolicy}"], "lacks 'policy'"),
    ("evaluate_edited_config", [*EVALUATE, "checkpoint={noobsdim}"], "policy.config builds no flownav policy"),
    ("train_edited_weights", [*TRAIN, "algo.init_from={noweight}"], "policy.state_dict lacks ['normalizer.mean']"),
    ("evaluate_no_such_checkpoint", [*EVALUATE, "checkpoint={tmp}/none.pt"], "no checkpoint at"),
    ("evaluate_not_a_checkpoint", [*EVALUATE, "checkpoint={garbage}"], "cannot read checkpoint"),
    ("evaluate_truncated_checkpoint", [*EVALUATE, "checkpoint={truncated}"], "cannot read checkpoint"),
    ("evaluate_sha256_type", [*EVALUATE, "flow.path={sha}"], "sha256"),
    ("evaluate_dt_string", [*EVALUATE, "flow.path={dt}"], "dt must be"),
    ("evaluate_bounds_without_lo", [*EVALUATE, "flow.path={lo}"], "bounds.lo"),
    ("train_sha256_type", [*TRAIN, "flow.path={sha}"], "sha256"),
    # data means what it says; the CFD generator's settings
    ("evaluate_bounds_beyond_grid", [*EVALUATE, "flow.path={beyond}"], "reach beyond the grid"),
    ("evaluate_shifted_origin", [*EVALUATE, "flow.path={shifted}"], "inside the declared obstacle"),
    ("evaluate_no_dataset", [*EVALUATE, "flow.path={tmp}/nothing"], "{tmp}/nothing"),
    ("cfd_frame_dt_fraction", [*CFD, "--frame-dt", "0.31", "--run-dir", "{tmp}/cfd1"], "--frame-dt"),
    ("cfd_warmup_fraction", [*CFD, "--warmup", "80.004", "--run-dir", "{tmp}/cfd2"], "--warmup"),
    ("cfd_warmup_negative", [*CFD, "--warmup", "-1", "--run-dir", "{tmp}/cfd3"], "--warmup"),
    ("cfd_record_zero", [*CFD, "--record", "0", "--run-dir", "{tmp}/cfd4"], "--record"),
    ("cfd_cells_zero", [*CFD, "--cells-per-d", "0", "--run-dir", "{tmp}/cfd5"], "--cells-per-d"),
    ("cfd_spacing_zero", [*CFD, "--out-spacing", "0", "--run-dir", "{tmp}/cfd6"], "--out-spacing"),
    ("cfd_span_zero", [*CFD, "--span", "0", "--run-dir", "{tmp}/cfd7"], "--span"),
    ("cfd_re_negative", [*CFD, "--re", "-3", "--run-dir", "{tmp}/cfd8"], "Re"),
    ("cfd_warmup_not_a_number", [*CFD, "--warmup", "abc", "--run-dir", "{tmp}/cfd10"], "--warmup"),
    ("cfd_unknown_command", ["-m", "flownav.cfd", "generat"], "invalid choice: 'generat'"),
    ("cfd_checkpoint_every_negative", [*CFD, "--checkpoint-every", "-1", "--run-dir", "{tmp}/cfd9"], "--checkpoint"),
    (
        "cfd_other_setup_in_run_dir",
        [*CFD, *TINY_CFD[:-2], "--out-spacing", "0.25", "--run-dir", "{cfd_run}"],
        "another set-up",
    ),
    # python -m flownav.export's own arguments
    ("export_format", [*EXPORT, "checkpoint=checkpoints/student.pt", "format=pdf"], "format=pdf"),
    ("export_no_checkpoint_arg", [*EXPORT, "format=onnx"], "checkpoint= is required"),
    ("export_unknown_argument", [*EXPORT, "checkpoint=checkpoints/student.pt", "outt=x"], "'outt=x'"),
    ("export_missing_policy_key", [*EXPORT, "checkpoint={nopolicy}", "out={tmp}/n.onnx"], "lacks 'policy'"),
    ("export_into_shipped_place", [*EXPORT, "checkpoint=checkpoints/student.pt", "out=checkpoints/s.onnx"], "shipped"),
    # weights holding an infinity, behind every loader; a key Hydra's + adds that nothing reads
    ("evaluate_nonfinite_weights", [*EVALUATE, "checkpoint={nonfinite}"], "NaN or infinity"),
    ("dagger_nonfinite_teacher", [*STUDENT, "teacher_checkpoint={nonfinite}"], "NaN or infinity"),
    ("train_nonfinite_init_from", [*TRAIN, "algo.init_from={nonfinite}"], "NaN or infinity"),
    ("export_nonfinite_weights", [*EXPORT, "checkpoint={nonfinite}", "out={tmp}/i.onnx"], "NaN or infinity"),
    ("train_unknown_env_key", [*TRAIN, "+env.sensor_nois.flow=0.1"], "unknown key 'sensor_nois'"),
    ("evaluate_unknown_flow_key", [*EVALUATE, "+flow.rotate=30"], "unknown key 'rotate'"),
]


class Evil:
    """Unpickling this runs a shell command that leaves a marker file."""

    def __init__(self, marker: Path):
        self.marker = marker

    def __reduce__(self):
        return (os.system, (f"touch {self.marker}",))


def make_files(tmp: Path) -> dict:
    """The checkpoints, run directories and datasets the cases point at."""
    import numpy as np
    import torch

    from flownav.agents import DeterministicPolicy
    from flownav.checkpoint import save_policy_checkpoint
    from flownav.envs.observations import observation_size
    from flownav.evaluation.scripted import ACTION_LOW, action_high
    from flownav.flows import Cylinder, load_grid_flow, save_grid_flow

    f = {"tmp": tmp, "marker": tmp / "marker"}
    # the teacher's view (geo_sincos) with hidden=[16]: the size differs from +experiment=teacher's
    small = DeterministicPolicy(observation_size("geo_sincos"), ACTION_LOW, action_high(), hidden=(16,), n_outputs=6)
    f["small"] = save_policy_checkpoint(tmp / "small.pt", small, "geo_sincos", "teacher")
    payload = torch.load(f["small"], weights_only=True)
    del payload["policy"]
    torch.save(payload, tmp / "nopolicy.pt")
    f["nopolicy"] = tmp / "nopolicy.pt"
    # hand-edited checkpoints: a config without obs_dim, weights without the normaliser's mean or infinite ones
    for name, edit in (
        ("noobsdim", lambda p: p["config"].pop("obs_dim")),
        ("noweight", lambda p: p["state_dict"].pop("normalizer.mean")),
        ("nonfinite", lambda p: p["state_dict"]["normalizer.mean"].fill_(float("inf"))),
    ):
        payload = torch.load(f["small"], weights_only=True)
        edit(payload["policy"])
        torch.save(payload, tmp / f"{name}.pt")
        f[name] = tmp / f"{name}.pt"
    (tmp / "garbage.pt").write_bytes(b"not a checkpoint at all")
    f["garbage"] = tmp / "garbage.pt"
    (tmp / "truncated.pt").write_bytes((ROOT / "checkpoints" / "student.pt").read_bytes()[:3000])  # a cut copy
    f["truncated"] = tmp / "truncated.pt"
    torch.save({"format": "flownav-policy-v1", "policy": Evil(f["marker"])}, tmp / "evil.pt")
    f["evil"] = tmp / "evil.pt"
    # a run directory (its config.yaml) whose last.pt is malicious; one whose last.pt is a good geo run's
    for name, ckpt in (("evil_run", f["evil"]), ("good_run", None)):
        run = tmp / name
        (run / "checkpoints").mkdir(parents=True)
        (run / "config.yaml").write_text("name: teacher\n")
        if ckpt is not None:
            (run / "checkpoints" / "last.pt").write_bytes(ckpt.read_bytes())
        f[name] = run
    geo = DeterministicPolicy(observation_size("geo"), ACTION_LOW, action_high(), hidden=(16,), n_outputs=6)
    save_policy_checkpoint(f["good_run"] / "checkpoints" / "last.pt", geo, "geo", "teacher")
    # a CFD run directory whose state.pt is malicious
    f["evil_cfd"] = tmp / "evil_cfd"
    f["evil_cfd"].mkdir()
    torch.save({"sim": Evil(f["marker"]), "run": {}}, f["evil_cfd"] / "state.pt")
    # a 3 x 3 x 2 grid around a cylinder at (1, 1): solid inside, a uniform stream outside; then broken metadata
    vel = np.zeros((2, 3, 3, 2, 3), np.float32)
    vel[..., 0] = 1.0
    vel[:, 1, 1] = 0.0
    edits = {
        "sha": lambda m: m.update(sha256="abc"),
        "dt": lambda m: m.update(dt="abc"),
        "lo": lambda m: m["bounds"].pop("lo"),
        "beyond": lambda m: m["bounds"].update(hi=[3.0, 2.0, 1.0]),
        "shifted": lambda m: m.update(origin=[0.0, 1.0, 0.0], bounds={"lo": [0.0, 1.0, 0.0], "hi": [2.0, 3.0, 1.0]}),
    }
    for name, edit in edits.items():
        f[name] = save_grid_flow(tmp / name, vel, (0, 0, 0), (1, 1, 1), 0.5, obstacles=[Cylinder((1.0, 1.0), 0.4)])
        assert load_grid_flow(f[name]).shape == (2, 3, 3, 2)  # the dataset loads before its metadata is broken
        meta = json.loads((f[name] / "meta.json").read_text())
        edit(meta)
        atomic_write_text(f[name] / "meta.json", json.dumps(meta))
    f["cfd_run"] = tmp / "cfd_run"  # filled by the first step of its case (a state of another set-up)
    return f


def prepare(case_id: str, files: dict) -> None:
    """Cases that need a state on disk first: a CFD run directory holding a run of another grid."""
    if case_id == "cfd_other_setup_in_run_dir" and not (files["cfd_run"] / "state.pt").exists():
        from flownav.cfd.runner import RunState, save_checkpoint
        from flownav.cfd.solver import CylinderLBM, SimConfig

        sim = CylinderLBM(SimConfig(re=100, cells_per_d=4, u_lattice=0.15, x_range=(-5, 27), y_half=7.5, span=2.0))
        save_checkpoint(files["cfd_run"] / "state.pt", sim, RunState())


def run_case(case, files: dict, timeout: float = 600) -> dict:
    """Run one case; return what a user would see and whether it is a one-line error."""
    case_id, argv, words = case
    prepare(case_id, files)
    argv = [a.format(**files) for a in argv]
    if argv[0] in ("train.py", "evaluate.py"):
        argv.append(f"hydra.run.dir={files['tmp'] / 'runs' / case_id}")
    env = {**os.environ, "FLOWNAV_DEBUG": "", "OMP_NUM_THREADS": "1", "WANDB_MODE": "offline"}
    t0 = time.time()
    out = subprocess.run(
        [sys.executable, *argv], cwd=ROOT, capture_output=True, text=True, timeout=timeout, env=env, check=False
    )
    lines = [ln for ln in out.stderr.splitlines() if ln.strip()]
    last = lines[-1] if lines else ""
    words = words.format(**files)
    ok = (
        out.returncode != 0
        and "Traceback" not in out.stderr
        and last.startswith("error: ")
        and words in last
        and not files["marker"].exists()
    )
    return {"id": case_id, "rc": out.returncode, "line": last, "ok": ok, "s": round(time.time() - t0, 1)}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("-k", default="", help="only the cases whose id contains this")
    p.add_argument("--json", type=Path, help="also write the table as JSON here")
    args = p.parse_args(argv)
    cases = [c for c in CASES if args.k in c[0]]
    before = tree_digest(*SHIPPED)
    with tempfile.TemporaryDirectory() as tmp:
        files = make_files(Path(tmp))
        rows = []
        for case in cases:
            row = run_case(case, files)
            rows.append(row)
            print(f"{'ok  ' if row['ok'] else 'FAIL'} {row['id']:32s} rc={row['rc']} {row['s']:5.1f}s  {row['line']}")
        ran_code = files["marker"].exists()
    after = tree_digest(*SHIPPED)
    changed = [k for k, v in after.items() if before.get(k) != v] + [k for k in before if k not in after]
    good = sum(r["ok"] for r in rows)
    print(f"{len(rows)} cases tried, {good} give a one-line error (exit status != 0, no traceback)")
    print(f"shipped files changed: {len(changed)}; code run from a malicious file: {ran_code}")
    if args.json:
        atomic_write_text(args.json, json.dumps({"rows": rows, "changed": changed, "ran_code": ran_code}, indent=1))
    return 0 if good == len(rows) and not changed and not ran_code else 1


if __name__ == "__main__":
    sys.exit(main())
