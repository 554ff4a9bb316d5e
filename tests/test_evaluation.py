"""Evaluation: exact episode counts, failure causes, Wilson intervals, subregion maps, the paper's suite at
tiny size, and refusal of a checkpoint of the wrong observation view."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
import torch
from hydra import compose, initialize_config_dir

from flownav.agents import DeterministicPolicy
from flownav.builders import compose_config
from flownav.checkpoint import CheckpointError, save_policy_checkpoint
from flownav.envs import NavigationEnv, RegionTask, Status
from flownav.envs.observations import observation_size
from flownav.evaluation.experiments import Suite
from flownav.evaluation.metrics import subregion_counts, summarize, wilson_interval
from flownav.evaluation.rollout import run_episodes
from flownav.evaluation.scripted import ACTION_LOW, HeadToTarget, action_high
from flownav.flows import Box, Cylinder, FunctionFlow, UniformFlow, save_grid_flow
from flownav.flows.base import WAKE_BOUNDS
from flownav.flows.synthetic import synthetic_wake_grid

ROOT = Path(__file__).resolve().parents[1]
EVAL_CONF = str(ROOT / "conf" / "evaluate")  # evaluate.py's config dir


def env_factory(flow, task, views=("geo",), **kw):
    kw = {"dt": 0.2, "time_limit": 20.0, "random_flow_phase": False} | kw

    def make_env(n, chunk):
        return NavigationEnv(flow, task, num_envs=n, views=views, seed=chunk, **kw)

    return make_env


def still(action):
    """A policy that always returns the same action."""
    a = torch.tensor(action)
    return lambda obs: a.expand(obs.shape[0], 3).clone()


# ----------------------------------------------------------------------------- Wilson
@pytest.mark.parametrize("k,n", [(0, 10), (5, 10), (10, 10), (9469, 10000), (1, 3), (0, 10000)])
def test_wilson_interval_solves_the_score_equation(k, n):
    """The Wilson bounds are the roots p of (k/n - p)^2 = z^2 p (1 - p) / n: solve it independently."""
    z = 1.959963984540054
    ph = k / n
    # (1 + z^2/n) p^2 - (2 ph + z^2/n) p + ph^2 = 0
    qa, qb, qc = 1 + z * z / n, -(2 * ph + z * z / n), ph * ph
    disc = math.sqrt(qb * qb - 4 * qa * qc)
    lo, hi = wilson_interval(k, n)
    assert lo == pytest.approx((-qb - disc) / (2 * qa), abs=1e-12)
    assert hi == pytest.approx((-qb + disc) / (2 * qa), abs=1e-12)


def test_wilson_interval_known_values():
    assert wilson_interval(0, 10) == (0.0, pytest.approx(0.2775327998628899, abs=1e-12))
    lo, hi = wilson_interval(5, 10)
    assert (lo, hi) == (pytest.approx(0.2365930905, abs=1e-9), pytest.approx(0.7634069095, abs=1e-9))
    assert wilson_interval(0, 0) == (0.0, 1.0)
    with pytest.raises(ValueError):
        wilson_interval(11, 10)


# ----------------------------------------------------------------------------- exact counts, failure causes
def test_exactly_n_episodes_and_pushed_out_of_the_domain():
    """A uniform stream of 1.5 along +x carries motionless swimmers out through the far x end at a known time."""
    flow = UniformFlow((1.5, 0.0, 0.0))
    ep = run_episodes(still([0.0, 0.0, 0.0]), "geo", env_factory(flow, RegionTask()), episodes=37, chunk_size=10)
    assert len(ep) == 37 and ep.start.shape == (37, 3)
    assert (ep.status == Status.LEFT_DOMAIN).all()
    x_end = WAKE_BOUNDS.hi[0]
    steps = torch.floor((x_end - ep.start[:, 0]) / (1.5 * 0.2)) + 1  # first step with x > x_end
    assert torch.allclose(ep.time, steps * 0.2, atol=1e-4)
    s = summarize(ep.status, ep.time)
    assert s["episodes"] == 37 and s["successes"] == 0
    assert s["failures"]["left_domain"]["count"] == 37 and s["failures"]["timeout"]["count"] == 0


def test_short_episodes_are_not_over_counted():
    """Half the swimmers leave fast, half time out: each slot still counts once (no auto-reset)."""
    flow = FunctionFlow(
        lambda p, t: torch.stack((torch.where(p[:, 1] > 3, 3.0, 0.0), 0 * p[:, 1], 0 * p[:, 2]), -1),
        bounds=WAKE_BOUNDS,  # at speed 3, x from [8, 12] leaves through x = 22 within the 6 time units
        max_speed=3.0,
    )
    task = RegionTask(Box((8.0, 2.0, 3.0), (12.0, 4.0, 7.0)), Box((8.0, -4.0, 3.0), (12.0, -2.0, 7.0)))
    ep = run_episodes(still([0.0, 0.0, 0.0]), "geo", env_factory(flow, task, time_limit=6.0), episodes=500)
    fast = ep.start[:, 1] > 3
    assert len(ep) == 500
    assert (ep.status[fast] == Status.LEFT_DOMAIN).all() and (ep.status[~fast] == Status.TIMEOUT).all()
    s = summarize(ep.status, ep.time)
    assert s["failures"]["left_domain"]["count"] == int(fast.sum())
    assert s["failures"]["timeout"]["count"] == int((~fast).sum())
    t_out = ep.time[~fast]
    # All time out together, at the limit: 30 steps of 0.2, not one step late.
    assert (t_out == t_out[0]).all() and float(t_out[0]) == pytest.approx(6.0, abs=1e-5)


def test_hit_the_cylinder_and_success():
    flow = FunctionFlow(
        lambda p, t: torch.tensor([1.0, 0.0, 0.0]).expand_as(p).clone(),
        bounds=WAKE_BOUNDS,
        max_speed=1.0,
        obstacles=[Cylinder((0.0, 0.0), 0.5)],
    )
    task = RegionTask(Box((-3.0, -0.2, 3.0), (-2.0, 0.2, 7.0)), Box((10.0, 4.0, 3.0), (12.0, 5.0, 7.0)))
    ep = run_episodes(still([0.0, 0.0, 0.0]), "geo", env_factory(flow, task), episodes=50)
    assert (ep.status == Status.HIT_OBSTACLE).all()
    assert summarize(ep.status, ep.time)["failures"]["hit_obstacle"]["count"] == 50
    # The scripted expert reaches targets 2-3 D away in still water.
    calm = UniformFlow((0.0, 0.0, 0.0))
    near = RegionTask(Box((5.0, 0.0, 5.0), (6.0, 1.0, 6.0)), Box((7.0, 0.0, 5.0), (8.0, 1.0, 6.0)))
    ep = run_episodes(HeadToTarget(), "geo", env_factory(calm, near, time_limit=30.0), episodes=200, chunk_size=64)
    s = summarize(ep.status, ep.time)
    assert s["success_rate"] > 0.95 and s["mean_success_time"] > 0


def test_rollout_is_deterministic_and_records_trajectories():
    flow = UniformFlow((0.3, 0.0, 0.0))
    make = env_factory(flow, RegionTask())
    a = run_episodes(HeadToTarget(), "geo", make, episodes=40, chunk_size=16, record=3)
    b = run_episodes(HeadToTarget(), "geo", make, episodes=40, chunk_size=16)
    assert torch.equal(a.status, b.status) and torch.equal(a.time, b.time)
    tr = a.trajectories
    assert tr["position"].shape[0] == 3 and tr["position"].shape[1] == tr["time"].shape[0]
    assert tr["action"].shape[1] == tr["position"].shape[1] - 1
    for i in range(3):  # the recording ends where the episode ended
        last = int(tr["alive"][i].nonzero().max())
        assert tr["time"][last] == pytest.approx(float(a.time[i]), abs=1e-5)
        assert torch.allclose(tr["position"][i, last], a.final_position[i])


def test_subregion_counts():
    box = Box((0.0, 0.0, 0.0), (10.0, 10.0, 10.0))
    start = torch.tensor([[0.5, 0.5, 0.5], [0.6, 0.2, 0.9], [9.99, 9.99, 9.99], [10.0, 5.0, 0.0]])
    success = torch.tensor([True, False, True, True])
    n, k = subregion_counts(start, success, box, (10, 10, 10))
    assert n.sum() == 4 and n[0, 0, 0] == 2 and k[0, 0, 0] == 1
    assert n[9, 9, 9] == 1 and k[9, 9, 9] == 1 and n[9, 5, 0] == 1  # the upper face belongs to the last cell


def test_ego_outcomes_do_not_depend_on_the_misalignment():
    """Rotating the whole scene about z leaves every ego observation, hence an ego policy's outcome, unchanged."""
    torch.manual_seed(0)
    flow = FunctionFlow(
        lambda p, t: torch.stack((0.6 + 0.3 * torch.sin(p[:, 1]), 0.3 * torch.cos(p[:, 0]), 0 * p[:, 2]), -1),
        bounds=WAKE_BOUNDS,
        max_speed=1.2,
    )
    ego = DeterministicPolicy(6, ACTION_LOW, action_high(), hidden=(16,))
    out = {}
    for angle in (0.0, 90.0):
        ep = run_episodes(
            ego, "ego", env_factory(flow, RegionTask(), views=("ego",), misalignment_deg=angle), episodes=300
        )
        out[angle] = ep
    assert torch.equal(out[0.0].status, out[90.0].status)
    assert torch.allclose(out[0.0].time, out[90.0].time, atol=1e-4)


# ----------------------------------------------------------------------------- evaluate.py and the suite
@pytest.fixture(scope="module")
def tiny_world(tmp_path_factory):
    """A small grid wake dataset and throwaway checkpoints of every view."""
    root = tmp_path_factory.mktemp("eval")
    data = save_grid_flow(root / "wake", **synthetic_wake_grid(frames=4, span_cells=6, span=12.0, frame_dt=1.0))
    torch.manual_seed(0)
    ck = {}
    for name, view, role in [
        ("teacher", "geo_sincos", "teacher"),
        ("student", "ego", "student"),
        ("baseline", "ego", "baseline"),
        ("teacher_symmetric", "geo_sincos", "teacher"),
        ("student_symmetric", "ego", "student"),
        ("teacher_flowobs", "geo_flow_sincos", "teacher"),
        ("student_flowobs", "ego_flow", "student"),
        ("student_up", "ego_up", "student"),
        ("student_mem", "ego_mem", "student"),
        ("teacher_abc", "geo", "teacher"),
        ("teacher_robust", "geo_sincos", "teacher"),
        ("student_robust", "ego", "student"),
        ("student_mem_robust", "ego_mem", "student"),
    ]:
        pol = DeterministicPolicy(observation_size(view), ACTION_LOW, action_high(), hidden=(16, 16))
        ck[name] = save_policy_checkpoint(root / f"{name}.pt", pol, view, role)
    return root, data, ck


def compose_eval(*overrides):
    with initialize_config_dir(config_dir=EVAL_CONF, version_base="1.3"):
        return compose("config", overrides=list(overrides))


def tiny_overrides(root, data, ck):
    return [
        f"flow.path={data}",
        "env.time_limit=3.0",
        "max_episodes=24",
        "chunk_size=16",
        "threads=1",
        f"results={root / 'paper.json'}",
        f"report={root / 'REPORT.md'}",
        f"figures_dir={root / 'figures'}",
    ] + [f"policies.{k}.checkpoint={v}" for k, v in ck.items()]


EXPERIMENTS = [
    "training",
    "extended",
    "symmetric",
    "flowobs",
    "misalignment",
    "time_limit",
    "still_water",
    "abc",
    "abc_ablation",
    "figures",
    "loss_curves",
]


@pytest.mark.parametrize("name", EXPERIMENTS)
def test_each_experiment_composes_and_runs_tiny(tiny_world, name):
    import evaluate

    root, data, ck = tiny_world
    extra = ["suite.figures.movie_frames=4"] if name == "figures" else []
    if name == "time_limit":
        extra = ["suite.time_limit.limits=[1,2,3]"]
    if name == "loss_curves":
        extra = [f"suite.loss_curves.run_globs=[{root}/runs/*/metrics.csv]", f"suite.loss_curves.json={root}/loss.json"]
        run = root / "runs" / "s0"
        run.mkdir(parents=True, exist_ok=True)
        (run / "metrics.csv").write_text("step,iteration,train/loss\n1,1,0.8\n2,2,0.3\n3,3,0.15\n")
    cfg = compose_eval(f"+experiment=paper_{name}", *tiny_overrides(root, data, ck), *extra)
    results = evaluate.run(cfg, log=lambda *_: None)
    r = results[name]
    assert not r["missing"], r["missing"]
    if name in ("training", "flowobs", "still_water", "abc", "extended", "symmetric"):
        for s in r["results"].values():
            assert s["episodes"] == 24
            assert s["successes"] + sum(f["count"] for f in s["failures"].values()) == 24
    if name == "misalignment":
        assert set(r["results"]["student"]) == {f"{a:g}" for a in range(0, 181, 15)}
    if name == "time_limit":  # one row per limit (what each row holds: test_time_limit_rows_equal_runs_at_that_limit)
        assert set(r["results"]["teacher"]) == {"1", "2", "3"}
    if name in ("figures", "extended", "misalignment", "abc_ablation", "loss_curves"):
        assert r["figures"] and all(Path(f).is_file() for f in r["figures"])
    if name == "loss_curves":
        assert json.loads((root / "loss.json").read_text())["mean"] == pytest.approx([0.8, 0.3, 0.15])
    data_json = json.loads((root / "paper.json").read_text())
    assert name in data_json["experiments"]
    assert (root / "REPORT.md").read_text().count("## ") >= 2


def test_paper_composes_every_experiment():
    cfg = compose_eval("+experiment=paper")
    assert list(cfg.suite) == EXPERIMENTS
    assert cfg.suite.training.episodes == 10000 and cfg.suite.extended.episodes == 50000
    assert cfg.suite.extended.task.target == [11.5, -3.5, 4.5]
    angles = list(cfg.suite.misalignment.angles)
    assert angles[0] == 0 and angles[-1] == 180 and max(np.diff(angles)) <= 15
    ratios = list(cfg.suite.abc_ablation.ratios)
    assert len(ratios) >= 6 and min(ratios) == pytest.approx(0.029) and max(ratios) == pytest.approx(0.29)
    assert cfg.suite.abc.env.swim_speed_scale == 0.1


def test_every_suite_entry_names_a_registered_kind_and_every_kind_is_used():
    """The kinds are the registry's (one module each in flownav/evaluation/kinds/); the configs use each of them."""
    from flownav.evaluation.kinds import KINDS, kind

    used = set()
    for path in sorted((ROOT / "conf" / "evaluate" / "experiment").glob("*.yaml")):
        cfg = compose_eval(f"+experiment={path.stem}")
        for name, spec in cfg.suite.items():
            assert kind(str(spec.kind)).name == spec.kind, f"{path.name}: suite.{name}"
            used.add(str(spec.kind))
    assert used == set(KINDS)
    modules = {p.stem for p in (ROOT / "flownav" / "evaluation" / "kinds").glob("*.py")} - {"__init__"}
    assert modules == set(KINDS)
    with pytest.raises(ValueError, match="choose one of"):
        kind("wander")


def test_time_limit_rows_equal_runs_at_that_limit(tiny_world):
    """One run at the longest limit, cut at a shorter one, gives exactly what a run at that limit gives."""
    import evaluate

    root, data, ck = tiny_world
    # Still water: the scripted navigator arrives after about its start distance (4 to 9), spread over the limits.
    calm = [o for o in tiny_overrides(root, data, ck) if not o.startswith("flow.")] + [
        "flow=uniform",
        "flow.velocity=[0,0,0]",
    ]
    base = [*calm, "max_episodes=64"]
    pols = "[head_to_target,teacher]"
    cfg = compose_eval(
        "+experiment=paper_time_limit", *base, "suite.time_limit.limits=[5,7,10]", f"suite.time_limit.policies={pols}"
    )
    sweep = evaluate.run(cfg, log=lambda *_: None)["time_limit"]["results"]
    for limit in ("5", "7"):
        cfg = compose_eval(
            "+experiment=paper_training", *base, f"env.time_limit={limit}", f"suite.training.policies={pols}"
        )
        direct = evaluate.run(cfg, log=lambda *_: None)["training"]["results"]
        for pol in ("head_to_target", "teacher"):
            cut = sweep[pol][limit]
            assert cut["successes"] == direct[pol]["successes"]
            assert cut["failures"] == direct[pol]["failures"]
            assert cut["mean_success_time"] == pytest.approx(direct[pol]["mean_success_time"])
    wins = [sweep["head_to_target"][k]["successes"] for k in ("5", "7", "10")]
    assert wins[0] < wins[1] < wins[2], wins  # each limit really cuts episodes short


def test_truncate_at_exact_small_case():
    from flownav.envs.navigation import Status
    from flownav.evaluation.metrics import truncate_at

    S, L, H, T = Status.SUCCESS, Status.LEFT_DOMAIN, Status.HIT_OBSTACLE, Status.TIMEOUT
    status = torch.tensor([S, S, L, H, T, S])
    time = torch.tensor([1.0, 2.2, 2.0, 3.0, 4.0, 2.0])
    assert truncate_at(status, time, 2.0, 0.2).tolist() == [S, T, L, T, T, S]


def test_missing_checkpoints_are_skipped_with_the_command(tiny_world, tmp_path):
    import evaluate

    root, data, ck = tiny_world
    cfg = compose_eval(
        "+experiment=paper_training",
        f"flow.path={data}",
        "max_episodes=8",
        "env.time_limit=2.0",
        f"results={tmp_path / 'p.json'}",
        f"report={tmp_path / 'R.md'}",
        f"figures_dir={tmp_path}",
        f"policies.teacher.checkpoint={tmp_path / 'none.pt'}",
        f"policies.student.checkpoint={ck['student']}",
        f"policies.baseline.checkpoint={ck['baseline']}",
        f"policies.student_up.checkpoint={ck['student_up']}",
        f"policies.student_mem.checkpoint={ck['student_mem']}",
        f"policies.teacher_robust.checkpoint={ck['teacher_robust']}",
        f"policies.student_robust.checkpoint={ck['student_robust']}",
        f"policies.student_mem_robust.checkpoint={ck['student_mem_robust']}",
    )
    r = evaluate.run(cfg, log=lambda *_: None)["training"]
    expected = {"student", "baseline", "student_up", "student_mem", "teacher_robust", "student_robust"}
    expected |= {"student_mem_robust", "generalist_teacher", "generalist_student", "generalist_student_noisy"}
    # (the generalists: their shipped files)
    expected |= {"head_to_target", "passive"}
    assert set(r["results"]) == expected  # no teacher file
    assert any("python train.py +experiment=teacher" in m for m in r["missing"])
    assert "python train.py +experiment=teacher" in (tmp_path / "R.md").read_text()


def test_single_checkpoint_and_wrong_view_is_refused(tiny_world, tmp_path):
    import evaluate

    root, data, ck = tiny_world
    cfg = compose_eval(
        f"checkpoint={ck['student']}",
        f"flow.path={data}",
        "episodes=30",
        "chunk_size=7",
        "env.time_limit=2.0",
        f"output={tmp_path / 's.json'}",
    )
    out = evaluate.run(cfg, log=lambda *_: None)
    assert out["episodes"] == 30 and json.loads((tmp_path / "s.json").read_text())["episodes"] == 30
    cfg = compose_eval(f"checkpoint={ck['teacher']}", "expect_obs=ego", f"flow.path={data}", "episodes=5")
    with pytest.raises(CheckpointError, match=r"reading 'geo_sincos'.*needs 'ego'"):
        evaluate.run(cfg, log=lambda *_: None)
    # In the suite, a checkpoint of the wrong view is skipped with the same message.
    cfg = compose_eval(
        "+experiment=paper_abc",
        "max_episodes=4",
        "env.time_limit=1.0",
        f"results={tmp_path / 'p.json'}",
        f"report={tmp_path / 'R.md'}",
        f"figures_dir={tmp_path}",
        f"policies.teacher.checkpoint={ck['teacher']}",
        f"policies.student.checkpoint={ck['teacher']}",
    )
    r = evaluate.run(cfg, log=lambda *_: None)["abc"]
    assert "teacher" in r["results"] and "student" not in r["results"]
    assert any("needs 'ego'" in m for m in r["missing"])


def test_example_episode_is_one_the_policies_solve():
    from flownav.evaluation.kinds.figures import pick_episode

    s, f = int(Status.SUCCESS), int(Status.TIMEOUT)
    runs = {"teacher": {"status": torch.tensor([f, s, s, f])}, "student": {"status": torch.tensor([s, f, s, s])}}
    assert pick_episode(runs, ["teacher", "student"]) == 2
    runs["teacher"]["status"] = torch.tensor([f, s, f, f])
    assert pick_episode(runs, ["teacher", "student"]) == 0  # none both solve: the student's first success
    assert pick_episode({"baseline": {"status": torch.tensor([f])}}, ["teacher"]) == 0


def test_report_puts_the_paper_next_to_ours(tmp_path):
    from omegaconf import OmegaConf

    from flownav.evaluation.report import merge_results, write_report
    from flownav.provenance import provenance

    training = OmegaConf.load(ROOT / "conf/evaluate/experiment/paper_training.yaml").suite.training

    status = torch.tensor([int(Status.SUCCESS)] * 9 + [int(Status.LEFT_DOMAIN)])
    s = summarize(status, torch.full((10,), 25.0))
    res = {
        "training": {
            "title": "a. Training flow",
            "kind": "success",
            "paper": {"student": {"success": 94.44, "time": 25.31}},
            "targets": OmegaConf.to_container(training.targets),  # the report's targets are the config's
            "results": {"student": s},
            "missing": [
                "teacher: missing checkpoint checkpoints/teacher.pt: run `python train.py +experiment=teacher`"
            ],
            "policies": {},
            "command": "python evaluate.py +experiment=paper_training",
        }
    }
    data = merge_results(tmp_path / "paper.json", res, provenance("python evaluate.py +experiment=paper"))
    text = write_report(data, tmp_path / "REPORT.md", "python evaluate.py +experiment=paper").read_text()
    lo, hi = wilson_interval(9, 10)
    assert "| student | 94.44% | 90.00% |" in text and f"[{100 * lo:.2f}, {100 * hi:.2f}]" in text
    assert "25.31 | 25.00 | 10.00%" in text
    assert "python evaluate.py +experiment=paper_training" in text and "+experiment=teacher" in text
    assert "Student in the training flow: 90.00% -> NOT met" in text
    assert json.loads((tmp_path / "paper.json").read_text())["experiments"]["training"]["provenance"]["commit"]
    # a run's report names its own results file, beside it
    beside = write_report(data, tmp_path / "REPORT.md", "python evaluate.py", results=tmp_path / "paper.json")
    assert "Machine-readable results: `paper.json`." in beside.read_text()


def test_the_performance_goal_counts_only_the_papers_experiments(tmp_path):
    """The <= 60-minute goal is for `+experiment=paper`: the zoo and the well-posed ABC are timed apart."""
    from flownav.evaluation.report import paper_suite_keys, write_report

    assert {"training", "extended", "abc", "loss_curves"} <= paper_suite_keys()
    assert not {"generalization", "abc_periodic"} & paper_suite_keys()
    exps = {k: {"title": k, "seconds": s} for k, s in [("training", 600), ("extended", 1200), ("generalization", 3000)]}
    text = write_report({"experiments": exps}, tmp_path / "REPORT.md", "python evaluate.py", seconds=90).read_text()
    assert "- This run of `evaluate.py`: 1.5 minutes." in text
    assert "The experiments of `+experiment=paper` below, as last run, took 30.0 minutes together (goal: <= 60" in text
    assert "- The other experiments below (`generalization`), as last run: 50.0 minutes." in text


def test_the_loss_curve_section_takes_the_papers_numbers_from_the_config_only(tmp_path):
    """Fig. 2c's paper curve is stated once in its REPORT.md section: the config's paper_ref, not the kind's code."""
    from omegaconf import OmegaConf

    from flownav.evaluation.report import merge_results, write_report
    from flownav.provenance import provenance

    spec = OmegaConf.load(ROOT / "conf/evaluate/experiment/paper_loss_curves.yaml").suite.loss_curves
    curve = {"runs": 2, "iteration": [1, 2, 3, 4, 5], "mean": [0.8, 0.5, 0.3, 0.2, 0.15], "std": [0.1] * 5}
    res = {
        "loss_curves": {
            "title": str(spec.title),
            "kind": "loss_curves",
            "paper_ref": "Fig. 2c (the paper's curve as the config states it)",
            "curve": curve,
            "missing": [],
            "policies": {},
        }
    }
    data = merge_results(tmp_path / "paper.json", res, provenance("python evaluate.py +experiment=paper"))
    text = write_report(data, tmp_path / "REPORT.md", "python evaluate.py +experiment=paper").read_text()
    section = text[text.index(f"## {spec.title}") :]
    assert "Paper: Fig. 2c (the paper's curve as the config states it)." in section
    assert section.count("paper") == 1, section  # the kind's own lines quote no paper numbers


def test_a_skipped_experiment_keeps_the_measured_result_it_would_replace(tmp_path):
    """A shipping run that lacks an input (here: the DAgger runs behind Fig. 2c, which live on the machine that
    trained them) skips that experiment; results/paper.json keeps what was measured, and the log says so."""
    from flownav.evaluation.report import merge_results
    from flownav.provenance import provenance

    cfg = compose_config(["+experiment=paper_loss_curves"], app="evaluate")
    cfg.suite.loss_curves.run_globs = [str(tmp_path / "none" / "*" / "metrics.csv")]
    cfg.suite.loss_curves.json = str(tmp_path / "student_loss.json")
    skipped = Suite(cfg, log=lambda *_: None).run("loss_curves", cfg.suite.loss_curves)
    assert skipped["skipped"] and "no DAgger runs found" in skipped["missing"][0]
    measured = {"kind": "loss_curves", "curve": {"runs": 5, "mean": [0.25, 0.2]}, "missing": [], "policies": {}}
    prov = provenance("python evaluate.py +experiment=paper")
    path, lines = tmp_path / "paper.json", []
    old_skip = {"kind": "success", "missing": ["missing checkpoint"], "skipped": True}
    merge_results(path, {"loss_curves": measured, "training": old_skip}, prov)
    data = merge_results(path, {"loss_curves": skipped, "training": skipped | {"kind": "success"}}, prov, lines.append)
    assert data["experiments"]["loss_curves"]["curve"] == measured["curve"]
    assert lines == [
        f"kept the measured result of loss_curves in {path} (this run skipped it: {skipped['missing'][0]})"
    ]
    assert data["experiments"]["training"]["missing"] == skipped["missing"]  # a skip replaces a skip...
    fresh = merge_results(tmp_path / "new.json", {"loss_curves": skipped}, prov)
    assert fresh["experiments"]["loss_curves"]["skipped"]  # ...or nothing


def test_provenance_is_the_code_before_the_run(tiny_world, monkeypatch, tmp_path):
    """The suite's own outputs (figures, results) are tracked files: the commit is read before they change."""
    import evaluate
    from flownav import provenance

    states = iter(["abc123", "abc123+dirty"])
    monkeypatch.setattr(provenance, "git_commit", lambda *a: next(states, "abc123+dirty"))
    root, data, ck = tiny_world
    own = [f"results={tmp_path / 'paper.json'}", f"report={tmp_path / 'REPORT.md'}"]  # not the shared ones
    cfg = compose_eval("+experiment=paper_training", *tiny_overrides(root, data, ck), *own)
    evaluate.run(cfg, log=lambda *_: None)
    assert (
        json.loads((tmp_path / "paper.json").read_text())["experiments"]["training"]["provenance"]["commit"] == "abc123"
    )
    text = (tmp_path / "REPORT.md").read_text()
    assert "at commit `abc123`" in text and "dirty" not in text
    assert "Machine-readable results: `paper.json`." in text  # the run's own results file, beside the report


def test_scripted_references_run_without_checkpoints(tiny_world):
    """The suite's scripted references need no checkpoint; a passive tracer in still water never arrives."""

    root, data, ck = tiny_world
    cfg = compose_eval("+experiment=paper_training", *tiny_overrides(root, data, ck))
    r = Suite(cfg, log=lambda *_: None).run("training", cfg.suite.training)
    assert {"head_to_target", "passive"} <= set(r["results"]) and not r["missing"]
    assert r["policies"]["passive"]["checkpoint"] == "scripted:passive"
    calm_overrides = [o for o in tiny_overrides(root, data, ck) if not o.startswith("flow.")]
    calm = compose_eval("+experiment=paper_training", *calm_overrides, "flow=uniform", "flow.velocity=[0,0,0]")
    still = Suite(calm, log=lambda *_: None).run("training", calm.suite.training)["results"]["passive"]
    assert still["failures"]["timeout"]["count"] == still["episodes"] == 24
    with pytest.raises(ValueError, match="choose one of"):
        Suite._scripted("mine", "wander")


def test_a_policy_is_the_same_policy_alone_and_in_a_combined_run():
    """Experiments combine into one run (`+experiment=[a,b,...]`, how REPORT.md is written) whose policies are one
    global group: an experiment that changed a policy's settings there would change every other experiment's rows of
    that policy, and their `Reproduce:` command (the experiment alone) would not give them. What a policy is
    (checkpoint or scripted reference, view, settings) and how many episodes of it an entry runs must not depend
    on the company."""
    every = sorted(p.stem for p in (ROOT / "conf" / "evaluate" / "experiment").glob("*.yaml") if p.stem != "paper")
    combined = compose_config([f"+experiment=[{','.join(every)}]"], app="evaluate")
    together = Suite(combined, log=lambda *_: None)
    identity = ("checkpoint", "scripted", "obs", "settings")
    for name in every:
        alone = compose_config([f"+experiment={name}"], app="evaluate")
        for suite, spec in alone.suite.items():
            for policy in spec.get("policies") or []:
                a, c = alone.policies[policy], combined.policies[policy]
                assert [a.get(k) for k in identity] == [c.get(k) for k in identity], (name, suite, policy)
                count = Suite(alone, log=lambda *_: None).episodes_of(spec, policy)
                assert count == together.episodes_of(combined.suite[suite], policy), (name, suite, policy)
    # the cap is the entry's: the well-posed ABC table's oracle runs 200 episodes, the time-limit study's 1000
    assert together.episodes_of(combined.suite.abc_periodic, "oracle_long") == 200
    assert together.episodes_of(combined.suite.abc_periodic_time_limit, "oracle_long") == 1000


def test_an_entrys_episode_caps_name_known_policies_and_are_counts():
    for caps, message in [
        ("{oracel: 3}", r"^suite\.training\.policy_episodes\.oracel: no policy 'oracel' in the config's policies \["),
        ("{passive: 0}", r"^suite\.training\.policy_episodes\.passive is 0; give a whole number of episodes >= 1$"),
    ]:
        overrides = ["+experiment=paper_training", "max_episodes=4", f"+suite.training.policy_episodes={caps}"]
        cfg = compose_config(overrides, app="evaluate")
        with pytest.raises(ValueError, match=message):
            Suite(cfg, log=lambda *_: None).run("training", cfg.suite.training)
