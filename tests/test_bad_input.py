# ruff: noqa: E501  (the expected messages are exact one-liners)
"""Every class of bad input fails with one line that names the key (or file) and the fix.

One parametrised test runs each case in-process and compares the exact message; a few representative
cases also run the entry points (train.py, evaluate.py, python -m flownav.cfd, python -m flownav.export) in a
subprocess: exit status 2, the line on stderr, no traceback (unless FLOWNAV_DEBUG=1). The full entry-point
census is scripts/bad_input_census.py (it also makes the files the cases here point at).
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest
import torch
from hydra import compose, initialize_config_dir
from load import load_module

from flownav.agents import DeterministicPolicy
from flownav.checkpoint import save_policy_checkpoint
from flownav.envs.observations import observation_size
from flownav.errors import FlownavError, one_line
from flownav.evaluation.scripted import ACTION_LOW, action_high
from flownav.flows import load_grid_flow

ROOT = Path(__file__).resolve().parents[1]
CONF = str(ROOT / "conf")
EVAL_CONF = str(ROOT / "conf" / "evaluate")
TINY = ["flow=uniform", "logger=csv", "logger.progress=false", "threads=1"]


def _census():
    """scripts/bad_input_census.py: the files every bad-input case points at, and the entry-point census."""
    return load_module("scripts/bad_input_census.py")


census = _census()


@pytest.fixture(scope="module")
def files(tmp_path_factory) -> dict:
    """Checkpoints, run directories and datasets the cases point at: {name: path} (the census script's, and a
    checkpoint whose critic has another size)."""
    root = tmp_path_factory.mktemp("bad")
    f = census.make_files(root)
    from flownav.agents.actor_critic import CriticNet

    actor = DeterministicPolicy(observation_size("geo_sincos"), ACTION_LOW, action_high(), hidden=(64, 64), n_outputs=6)
    critic = {"critic": CriticNet(observation_size("geo_sincos"), [32], "tanh").state_dict()}
    f["critic"] = save_policy_checkpoint(root / "critic.pt", actor, "geo_sincos", "teacher", train_state=critic)
    return f


def train_case(*overrides, experiment="teacher"):
    def run(files, tmp_path):
        from train import run as train_run

        with initialize_config_dir(config_dir=CONF, version_base="1.3"):
            overrides_ = [f"+experiment={experiment}", *TINY, *(o.format(**files) for o in overrides)]
            cfg = compose("config", overrides=overrides_)
        train_run(cfg, tmp_path)

    return run


def dagger_case(*overrides):
    return train_case("teacher_checkpoint=checkpoints/teacher.pt", *overrides, experiment="student")


def evaluate_case(*overrides):
    def run(files, tmp_path):
        import evaluate

        with initialize_config_dir(config_dir=EVAL_CONF, version_base="1.3"):
            cfg = compose("config", overrides=["episodes=4", *(o.format(**files) for o in overrides)])
        evaluate.run(cfg, log=lambda *_: None)

    return run


def data_case(name):
    def run(files, tmp_path):
        load_grid_flow(files[name])

    return run


def cfd_case(*argv):
    def run(files, tmp_path):
        from flownav.cfd.__main__ import _run, parser

        _run(parser().parse_args(["generate", "--run-dir", str(tmp_path), *(a.format(**files) for a in argv)]))

    return run


def export_case(*argv):
    def run(files, tmp_path):
        from flownav.export import export_policy, parse_arguments

        args = parse_arguments([a.format(**files) for a in argv])
        export_policy(args["checkpoint"], args["format"], args["out"] or tmp_path / "policy.onnx")

    return run


# The tests' tiny wake lattice: passes GenerateConfig.check, builds in a second.
TINY_CFD = "--re 100 --cells-per-d 4 --u-lattice 0.15 --x-range -5 26 --y-half 7.5 --span 2".split()
TINY_CFD += "--warmup 12 --record 14 --frame-dt 0.45 --out-spacing 0.5".split()


def without_cuda(case):
    def run(files, tmp_path):
        if torch.cuda.is_available():
            pytest.skip("this machine has CUDA")
        case(files, tmp_path)

    return run


SHA = "{sha}/meta.json"
EVIL = "refused to load {evil}: it asks for posix.system, which loading could run as code; load only checkpoints written by flownav (tensors, numbers, strings, lists, dicts)"
EVIL_RUN = EVIL.replace("{evil}", "{evil_run}/checkpoints/last.pt")
# (id, case, the exact message after "error: ")
CASES = [
    # wrong types and silent coercions
    ("int_abc", train_case("algo.total_frames=abc"), "algo.total_frames must be >= 1, an integer; got 'abc'"),
    ("int_fraction", train_case("algo.epochs=1.5"), "algo.epochs must be >= 1, an integer; got 1.5"),
    ("seed_abc", train_case("seed=abc"), "seed must be an integer; got 'abc'"),
    (
        "bool_word",
        train_case("env.random_flow_phase=maybe"),
        "env.random_flow_phase must be true or false; got 'maybe'",
    ),
    (
        "sensor_noise_negative",
        train_case("env.sensor_noise.flow=-0.1"),
        "env.sensor_noise.flow must be >= 0, a finite number; got -0.1",
    ),
    (
        "gradient_noise_negative",
        train_case("env.sensor_noise.gradient=-0.02"),
        "env.sensor_noise.gradient must be >= 0, a finite number or null; got -0.02",
    ),
    (
        "sensor_bias_negative",
        train_case("env.sensor_bias.flow=-0.1"),
        "env.sensor_bias.flow must be >= 0, a finite number or null; got -0.1",
    ),
    (
        "sensor_bias_frame_unknown",
        train_case("env.sensor_bias.frame=up"),
        "env.sensor_bias.frame is 'up'; choose one of ['body', 'world']",
    ),
    (
        "hidden_zero",
        train_case("algo.actor.hidden=[0]"),
        "algo.actor.hidden must be a non-empty list of integers, each >= 1; got [0]",
    ),
    # non-finite floats
    ("reward_nan", train_case("env.reward.alpha=nan"), "env.reward.alpha must be >= 0, a finite number; got nan"),
    (
        "bonus_inf",
        train_case("env.reward.success_bonus=inf"),
        "env.reward.success_bonus must be a finite number; got inf",
    ),
    ("entropy_nan", train_case("algo.entropy_coeff=nan"), "algo.entropy_coeff must be >= 0, a finite number; got nan"),
    ("misalign_nan", train_case("env.misalignment_deg=nan"), "env.misalignment_deg must be a finite number; got nan"),
    ("grad_clip_nan", dagger_case("algo.grad_clip=nan"), "algo.grad_clip must be >= 0, a finite number; got nan"),
    # a key no group has (Hydra's + adds any key)
    (
        "env_key_unknown",
        train_case("+env.sensor_nois.flow=0.1"),
        "env has an unknown key 'sensor_nois'; keys: ['num_envs', 'dt', 'time_limit', 'u_max', 'swim_speed_scale', 'misalignment_deg', 'random_flow_phase', 'flow_strength', 'flow_strength_full', 'sensor_noise', 'sensor_bias', 'reward']",
    ),
    (
        "flow_key_unknown",
        train_case("+flow.rotate=30"),
        "flow has an unknown key 'rotate'; keys: ['type', 'speed_scale', 'periodic_axes', 'rotate_deg', 'rotate_center', 'velocity', 'bounds']",
    ),
    (
        "task_key_unknown",
        train_case("+task.regions_share=0.5"),
        "task has an unknown key 'regions_share'; keys: ['type', 'in_pi', 'start', 'target']",
    ),
    # zero, negative, infinite
    ("num_envs_zero", train_case("env.num_envs=0"), "env.num_envs must be >= 1, an integer; got 0"),
    ("time_limit_inf", train_case("env.time_limit=inf"), "env.time_limit must be > 0, a finite number; got inf"),
    ("log_every_zero", train_case("algo.log_every=0"), "algo.log_every must be >= 1, an integer; got 0"),
    ("dt_negative", train_case("env.dt=-0.2"), "env.dt must be > 0, a finite number; got -0.2"),
    ("threads_zero", train_case("threads=0"), "threads must be >= 1, an integer or null; got 0"),
    ("speed_scale_zero", train_case("flow.speed_scale=0"), "flow.speed_scale must be > 0, a finite number; got 0"),
    ("gamma_range", train_case("algo.gamma=1.5"), "algo.gamma must be in (0, 1], a finite number; got 1.5"),
    (
        "clip_epsilon_zero",
        train_case("algo.clip_epsilon=0"),
        "algo.clip_epsilon must be in (0, 1), a finite number; got 0",
    ),
    (
        "strength_order",
        train_case("env.flow_strength=[0.5,0.2]"),
        "env: flow_strength must be [low, high] with 0 <= low <= high, got (0.5, 0.2)",
    ),
    (
        "box_inverted",
        train_case("task.start=[[1,2,3],[0,5,6]]"),
        "task.start must be [[x0, y0, z0], [x1, y1, z1]] with x1 > x0 etc.; got [[1, 2, 3], [0, 5, 6]]",
    ),
    ("episodes_zero", evaluate_case("episodes=0"), "episodes must be >= 1, an integer; got 0"),
    (
        "sensing_radius_zero",
        train_case("+algo.oracle_settings.sensing_radius=0", experiment="oracle_imitator"),
        "algo.oracle_settings.sensing_radius must be > 0, a finite number or null; got 0",
    ),
    # choices and a key tied to another
    (
        "critic_loss_unknown",
        train_case("algo.loss_critic_type=l3"),
        "algo.loss_critic_type is 'l3'; choose one of ['l1', 'l2', 'smooth_l1']",
    ),
    (
        "activation_unknown",
        train_case("algo.actor.activation=sigmoid"),
        "algo.actor.activation is 'sigmoid'; choose one of ['elu', 'relu', 'silu', 'tanh']",
    ),
    (
        "view_unknown",
        train_case("obs.view=sonar"),
        "obs.view is 'sonar'; choose one of ['ego', 'ego_flow', 'ego_mem', 'ego_mem_grad', 'ego_mem_grad_track', 'ego_mem_speed', 'ego_up', 'geo', 'geo_flow', 'geo_flow_sincos', 'geo_priv', 'geo_priv_around', 'geo_priv_critic', 'geo_priv_scene', 'geo_priv_wake', 'geo_sincos', 'privileged']",
    ),
    (
        "algo_unknown",
        train_case("algo.name=sac"),
        "algo.name is 'sac'; choose one of ['dagger', 'oracle_dagger', 'ppo']",
    ),
    (
        "wandb_mode",
        train_case("logger.wandb.mode=sometimes"),
        "logger.wandb.mode is 'sometimes'; choose one of ['disabled', 'offline', 'online']",
    ),
    (
        "minibatch",
        train_case("algo.minibatch_size=100000000"),
        "algo.minibatch_size (100000000) exceeds a batch of env.num_envs x algo.rollout_steps = 32768",
    ),
    (
        "task_not_fitting_flow",
        train_case("flow=abc", "algo.total_frames=1"),
        "task= does not fit flow=: after 100 draws some of the task's starts still lie outside the flow's domain, inside an obstacle or within env.reward.success_radius of their target; pick a task made for this flow (e.g. flow=abc with task=abc, as +experiment=teacher_abc does)",
    ),
    # devices
    (
        "cuda",
        without_cuda(train_case("device=cuda")),
        "device=cuda asks for CUDA but torch sees no CUDA device here; use device=cpu",
    ),
    ("device_typo", evaluate_case("device=gpu"), "device=gpu is not a torch device (cpu, cuda, cuda:0)"),
    # checkpoints
    (
        "hidden_mismatch",
        train_case("algo.init_from={small}", "algo.total_frames=1"),
        "the checkpoint's network was trained with hidden=[16] (9 inputs, 6 outputs) but this one has hidden=[64, 64] (9 inputs, 6 outputs): set algo.actor.hidden=[16] (PPO) or algo.hidden=[16] (DAgger) or use a checkpoint of this size",
    ),
    (
        "critic_mismatch",
        train_case("algo.init_from={critic}", "algo.total_frames=1"),
        "the checkpoint's network was trained with hidden=[32] (9 inputs, 1 outputs) but this one has hidden=[64, 64] (9 inputs, 1 outputs): set algo.critic.hidden=[32] or use a checkpoint of this size",
    ),
    (
        "missing_policy",
        evaluate_case("checkpoint={nopolicy}"),
        "{nopolicy} lacks 'policy': it is an incomplete flownav-policy-v1 checkpoint; use the run's last.pt or best.pt, or a file written by save_policy_checkpoint",
    ),
    (
        "no_checkpoint",
        evaluate_case("checkpoint={marker}.pt"),
        "no checkpoint at {marker}.pt: train one (python train.py +experiment=teacher) or fix the path",
    ),
    ("malicious", evaluate_case("checkpoint={evil}"), EVIL),
    (
        "edited_config",
        evaluate_case("checkpoint={noobsdim}"),
        "{noobsdim}: policy.config builds no flownav policy (DeterministicPolicy.__init__() missing 1 required positional argument: 'obs_dim'); the file is corrupt or was edited; use the run's last.pt or best.pt, or a file written by flownav",
    ),
    (
        "edited_weights",
        train_case("algo.init_from={noweight}", "algo.total_frames=1"),
        "{noweight}: policy.state_dict lacks ['normalizer.mean'] for its policy.config; the file is corrupt or was edited; use the run's last.pt or best.pt, or a file written by flownav",
    ),
    (
        "nonfinite_weights",
        evaluate_case("checkpoint={nonfinite}"),
        "{nonfinite} has NaN or infinity in policy.state_dict.normalizer.mean; use a checkpoint written by flownav (it refuses to save such weights)",
    ),
    (
        "nonfinite_teacher",
        dagger_case("teacher_checkpoint={nonfinite}"),
        "{nonfinite} has NaN or infinity in policy.state_dict.normalizer.mean; use a checkpoint written by flownav (it refuses to save such weights)",
    ),
    (
        "nonfinite_export",
        export_case("checkpoint={nonfinite}"),
        "{nonfinite} has NaN or infinity in policy.state_dict.normalizer.mean; use a checkpoint written by flownav (it refuses to save such weights)",
    ),
    (
        "not_a_checkpoint",
        evaluate_case("checkpoint={garbage}"),
        "cannot read checkpoint {garbage}: it is truncated, corrupt or not a torch file (nothing a weights-only load can read); use a checkpoint written by flownav (a run's checkpoints/last.pt or best.pt)",
    ),
    (
        "truncated_checkpoint",
        evaluate_case("checkpoint={truncated}"),
        "cannot read checkpoint {truncated}: it is truncated, corrupt or not a torch file (PytorchStreamReader failed reading zip archive: failed finding central directory); use a checkpoint written by flownav (a run's checkpoints/last.pt or best.pt)",
    ),
    # a malicious pickle behind every loader: teacher, init_from, resume (PPO; DAgger, whose buffer is in
    # last.pt), the CFD run state, the exporter
    ("malicious_teacher", dagger_case("teacher_checkpoint={evil}"), EVIL),
    ("malicious_init_from", train_case("algo.init_from={evil}"), EVIL),
    ("malicious_resume_ppo", train_case("resume={evil_run}"), EVIL_RUN),
    ("malicious_resume_dagger", dagger_case("resume={evil_run}"), EVIL_RUN),
    (
        "malicious_cfd_state",
        cfd_case(*TINY_CFD, "--run-dir", "{evil_cfd}"),
        EVIL.replace("{evil}", "{evil_cfd}/state.pt"),
    ),
    ("malicious_export", export_case("checkpoint={evil}"), EVIL),
    (
        "export_to_shipped",
        export_case("checkpoint=checkpoints/student.pt", "out=checkpoints/student.onnx"),
        "out=checkpoints/student.onnx is in a shipped place (checkpoints/, results/, data/ or REPORT.md); write the export elsewhere, e.g. the default exports/",
    ),
    (
        "export_format",
        export_case("checkpoint=checkpoints/student.pt", "format=pdf"),
        "format=pdf: choose one of onnx, torchscript",
    ),
    # datasets
    ("sha256_type", data_case("sha"), SHA + ": sha256 must be a group of keys (['velocity.npy']); got 'abc'"),
    ("dt_string", data_case("dt"), "{dt}/meta.json: dt must be > 0, a finite number; got 'abc'"),
    ("bounds_no_lo", data_case("lo"), "{lo}/meta.json: bounds.lo is missing; set it to a list of 3 finite numbers"),
    (
        "bounds_beyond",
        data_case("beyond"),
        "{beyond}/meta.json: bounds in x [0, 3] reach beyond the grid's [0, 2] on a non-periodic axis (the edge velocity would be held constant there): shrink bounds to the grid, or check origin and spacing",
    ),
    (
        "obstacle_moving",
        data_case("shifted"),
        "{shifted}/meta.json: the flow moves at up to 1 inside the declared obstacle {{'type': 'cylinder', 'center': [1.0, 1.0], 'radius': 0.4}} (max speed 1); a shifted origin or wrong obstacles: fix origin/obstacles",
    ),
    # the CFD generator
    (
        "cfd_frame_dt",
        cfd_case("--frame-dt", "0.31"),
        "frame_dt (--frame-dt) = 0.31 D/U is 37.2 lattice steps of 0.00833333 D/U; use a whole number of steps, e.g. 0.308333",
    ),
    ("cfd_warmup_zero", cfd_case("--warmup", "0"), "warmup (--warmup) must be a positive number of D/U, got 0.0"),
    ("cfd_cells_zero", cfd_case("--cells-per-d", "0"), "cells_per_d (--cells-per-d) must be a positive number, got 0"),
    (
        "cfd_spacing_zero",
        cfd_case("--out-spacing", "0"),
        "out_spacing (--out-spacing) must be a positive number of D, got 0.0",
    ),
    ("cfd_checkpoint_every", cfd_case("--checkpoint-every", "-1"), "--checkpoint-every must be >= 0 seconds, got -1.0"),
]


@pytest.mark.parametrize("case, expected", [pytest.param(c, e, id=i) for i, c, e in CASES])
def test_bad_input_gives_one_line_naming_the_key(case, expected, files, tmp_path):
    with pytest.raises(FlownavError) as err:
        case(files, tmp_path)
    assert one_line(err.value) == "error: " + expected.format(**files)
    assert "\n" not in str(err.value)
    assert not files["marker"].exists()  # nothing ran from a checkpoint


CFD = "python -m flownav.cfd"


@pytest.mark.parametrize(
    "argv, expected",
    [
        (
            ["generate", "--warmup", "abc"],
            f"{CFD} generate: argument --warmup: invalid float value: 'abc'; see {CFD} generate --help",
        ),
        (
            ["generat"],
            f"{CFD}: argument cmd: invalid choice: 'generat' (choose from 'generate', 'validate', 'plot'); "
            f"see {CFD} --help",
        ),
    ],
    ids=["not_a_number", "unknown_command"],
)
def test_cfd_argument_errors_are_one_line(argv, expected, capsys):
    from flownav.cfd.__main__ import parser

    with pytest.raises(SystemExit) as stop:
        parser().parse_args(argv)
    assert stop.value.code == 2 and capsys.readouterr().err == f"error: {expected}\n"


def _entry_point(args, **env):
    return subprocess.run(
        [sys.executable, *args],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=300,
        env={**os.environ, "FLOWNAV_DEBUG": "", **env},
    )


@pytest.mark.slow
@pytest.mark.parametrize(
    "args, expected",
    [
        (["train.py", "+experiment=teacher", "algo.epochs=1.5"], "algo.epochs must be >= 1, an integer; got 1.5"),
        (
            ["train.py", "+experiment=teacher", "env.reward.alpha=nan"],
            "env.reward.alpha must be >= 0, a finite number; got nan",
        ),
        (
            ["evaluate.py", "checkpoint={evil}"],
            "refused to load {evil}: it asks for posix.system, which loading could run as code; load only checkpoints written by flownav (tensors, numbers, strings, lists, dicts)",
        ),
        (
            ["-m", "flownav.cfd", "generate", "--warmup", "-1"],
            "warmup (--warmup) must be a positive number of D/U, got -1.0",
        ),
    ],
    ids=["train_fraction", "train_nan", "evaluate_malicious", "cfd_negative"],  # the exporter: the census test
)
def test_entry_points_print_one_line_and_exit_2(args, expected, files, tmp_path):
    args = [a.format(**files) for a in args]
    if args[0] in ("train.py", "evaluate.py"):
        args.append(f"hydra.run.dir={tmp_path}")
    out = _entry_point(args)
    assert out.returncode == 2, out.stderr[-2000:]
    assert out.stderr.strip().splitlines()[-1] == "error: " + expected.format(**files)
    assert "Traceback" not in out.stderr
    assert not files["marker"].exists()


@pytest.mark.slow
def test_census_script_counts_its_cases():
    """The census runs (one of its cases here, the exporter given a malicious checkpoint, through its entry point;
    all of them: python scripts/bad_input_census.py)."""
    assert len(census.CASES) >= 45 and len({c[0] for c in census.CASES}) == len(census.CASES)
    out = _entry_point(["scripts/bad_input_census.py", "-k", "export_evil"])
    assert out.returncode == 0, out.stdout + out.stderr[-2000:]
    assert "1 cases tried, 1 give a one-line error" in out.stdout and "shipped files changed: 0" in out.stdout


@pytest.mark.slow
def test_debug_switch_shows_the_traceback(tmp_path):
    out = _entry_point(
        ["-m", "flownav.cfd", "generate", "--warmup", "-1", "--run-dir", str(tmp_path)], FLOWNAV_DEBUG="1"
    )
    assert out.returncode != 0 and "Traceback" in out.stderr and "ConfigError: warmup (--warmup)" in out.stderr


def test_every_shipped_checkpoint_loads_without_running_code():
    from flownav.checkpoint import load_policy

    shipped = sorted((ROOT / "checkpoints").glob("*.pt"))
    assert len(shipped) >= 10
    for path in shipped:
        policy, payload = load_policy(path)  # weights_only=True: tensors and plain data only
        assert payload["obs"] and policy.config["obs_dim"] == observation_size(payload["obs"])


def test_no_loader_in_the_package_allows_code():
    sources = [*(ROOT / "flownav").rglob("*.py"), ROOT / "train.py", ROOT / "evaluate.py"]
    calls = [p for p in sources if "torch.load(" in p.read_text()]
    assert [p.relative_to(ROOT).as_posix() for p in calls] == ["flownav/checkpoint.py"]  # safe_torch_load only
    assert "weights_only=False" not in (ROOT / "flownav" / "checkpoint.py").read_text()


def test_every_shipped_config_passes_the_schema():
    from flownav import schema

    with initialize_config_dir(config_dir=CONF, version_base="1.3"):
        for experiment in sorted(p.stem for p in (ROOT / "conf" / "experiment").glob("*.yaml")):
            schema.check_train(compose("config", overrides=[f"+experiment={experiment}"]))
    with initialize_config_dir(config_dir=EVAL_CONF, version_base="1.3"):
        for suite in sorted(p.stem for p in (ROOT / "conf" / "evaluate" / "experiment").glob("*.yaml")):
            cfg = compose("config", overrides=[f"+experiment={suite}"])
            schema.check_evaluate(cfg)
            for spec in cfg.suite.values():
                for key, check in (("flow", schema.check_flow), ("task", schema.check_task)):
                    if key in spec:
                        check(spec[key])
