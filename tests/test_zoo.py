"""The generalisation zoo and the validation set: incompressible held-out flows, none a member of a training family,
the validation set's none of the zoo's kinds, and the suites."""

import json
import math

import pytest
import torch
from hydra import compose, initialize_config_dir
from omegaconf import OmegaConf

from flownav.builders import build_flow, build_task, compose_config
from flownav.evaluation.experiments import Suite, run_suite
from flownav.evaluation.kinds.zoo import family_member
from flownav.flows.validation import J1_ZERO, VALIDATION, BickleyJet, HillVortex, LambDipole
from flownav.flows.zoo import ZOO, BeltramiShell
from flownav.paths import REPO_ROOT

EVAL_CONF = str(REPO_ROOT / "conf" / "evaluate")  # evaluate.py's config dir


def compose_eval(*overrides):
    with initialize_config_dir(config_dir=EVAL_CONF, version_base="1.3"):
        return compose("config", overrides=list(overrides))


def jacobian(flow, n=64, seed=0):
    """du_i / dx_j at random points and times of the box, by autograd (float64): ``[n, 3, 3]`` and the velocity."""
    g = torch.Generator().manual_seed(seed)
    pos = flow.bounds.sample(n, g).double().requires_grad_(True)
    t = torch.rand(n, generator=g, dtype=torch.float64) * 20
    u = flow.velocity(pos, t)
    rows = [torch.autograd.grad(u[:, i].sum(), pos, retain_graph=True)[0] for i in range(3)]
    return torch.stack(rows, 1), u.detach(), pos.detach()


@pytest.mark.parametrize("name", sorted(ZOO) + sorted(VALIDATION))
def test_every_held_out_flow_is_incompressible_and_weaker_than_the_swimmer_on_average(name):
    flow = (ZOO | VALIDATION)[name]()
    J, u, _ = jacobian(flow)
    div = J.diagonal(dim1=1, dim2=2).sum(-1)
    scale = J.abs().amax()
    assert scale > 0.01  # not a trivially uniform flow
    assert div.abs().max() < 1e-9 * max(1.0, float(scale))
    assert 0.3 < flow.mean_speed < 1.0 <= 2.5 * flow.mean_speed and flow.max_speed >= flow.mean_speed


def test_beltrami_shell_is_beltrami_with_eigenvalue_minus_k0():
    flow = BeltramiShell(seed=3, k0=1.7)
    J, u, _ = jacobian(flow)
    curl = torch.stack((J[:, 2, 1] - J[:, 1, 2], J[:, 0, 2] - J[:, 2, 0], J[:, 1, 0] - J[:, 0, 1]), -1)
    assert torch.allclose(curl, -1.7 * u, atol=1e-9)


def test_burgers_vortex_is_the_textbook_field():
    flow = ZOO["burgers_vortex"](circulation=2 * math.pi, core=1.0, strain=0.1)
    cx, cy, cz = flow.center
    pos = torch.tensor([[cx + 2.0, cy, cz + 1.0]], dtype=torch.float64)
    u = flow.velocity(pos, torch.zeros(1, dtype=torch.float64))[0]
    # u_r = -alpha r / 2 = -0.1, u_theta = Gamma / (2 pi r) (1 - e^{-r^2}) = (1 - e^{-4}) / 2, u_z = alpha z = 0.1
    assert u.tolist() == pytest.approx([-0.1, (1 - math.exp(-4)) / 2, 0.1])


def test_the_validation_flows_are_the_textbook_fields():
    """Exact values: the Bickley jet's centre line moves at U whatever its waves; Hill's vortex turns the stream
    back at its centre (1.5 U against it) and is continuous across its sphere; the Lamb-Chaplygin dipole (alone: no
    images in reach) moves its centre at U (1 - 1 / J0(k a)) and is continuous across its circle."""
    t0 = torch.zeros(1, dtype=torch.float64)
    jet = BickleyJet()
    for x in (0.0, 3.3, 11.0):
        u = jet.velocity(torch.tensor([[x, jet.y0, 1.0]], dtype=torch.float64), t0 + x)[0]
        assert u[0].item() == pytest.approx(jet.U) and u[2].item() == 0.0
    hill = HillVortex(U=0.5, radius=3.0)
    centre = torch.tensor([hill.center], dtype=torch.float64)
    assert hill.velocity(centre, t0)[0].tolist() == pytest.approx([0.75, 0.0, 0.0])
    dipole = LambDipole(U=0.5, radius=3.0, spacing=1e6)
    x0, y0 = dipole.start
    centre = torch.tensor([[x0, y0, 0.0]], dtype=torch.float64)
    j0 = float(torch.special.bessel_j0(torch.tensor(J1_ZERO, dtype=torch.float64)))
    assert dipole.velocity(centre, t0)[0].tolist() == pytest.approx([0.5 * (1 - 1 / j0), 0.0, 0.0], abs=1e-9)
    angles = torch.linspace(0.1, 3.0, 7, dtype=torch.float64)
    sphere = torch.stack((torch.cos(angles), 0.6 * torch.sin(angles), 0.8 * torch.sin(angles)), -1)
    circle = torch.stack((torch.cos(angles), torch.sin(angles), torch.zeros_like(angles)), -1)
    for flow, origin, ring in ((hill, hill.center, sphere), (dipole, (x0, y0, 0.0), circle)):
        origin = torch.tensor(origin, dtype=torch.float64)
        inner, outer = (flow.velocity(origin + r * ring, t0.expand(7)) for r in (3.0 - 1e-7, 3.0 + 1e-7))
        assert torch.allclose(inner, outer, atol=1e-5), type(flow).__name__
        assert inner.abs().max() > 0.1  # a boundary where the flow moves


def test_no_validation_case_is_a_zoo_flow_or_a_member_of_a_training_family():
    """The validation set is for choices: its flows must be of kinds neither trained on nor reported (the zoo)."""
    families = OmegaConf.to_container(compose_eval("+experiment=generalization").suite.generalization.training_families)
    cfg = compose_eval("+experiment=validation")
    assert not set(VALIDATION) & set(ZOO) and not set(VALIDATION.values()) & set(ZOO.values())
    assert all(fam["type"] != "validation" for fam in families)  # no family draws a validation flow
    g = torch.Generator().manual_seed(0)
    for case, cs in cfg.suite.validation.cases.items():
        assert cs.flow.type == "validation" and cs.flow.name in VALIDATION, case
        flow = build_flow(cs.flow)
        start, target = build_task(cs.task, flow).sample(500, g)
        d = (target - start).norm(dim=-1)
        assert 8.0 <= float(d.min()) and float(d.max()) <= 12.0, case
    assert len(cfg.suite.validation.cases) == len(VALIDATION)


def test_no_zoo_case_is_a_member_of_a_training_family_unless_it_says_so():
    cfg = compose_eval("+experiment=generalization")
    spec = cfg.suite.generalization
    families = OmegaConf.to_container(spec.training_families)
    held = 0
    for case, cs in spec.cases.items():
        env = OmegaConf.merge(cfg.env, cs.get("env") or {})
        assert family_member(cs.flow, env, families) == cs.get("in_family"), case
        held += cs.get("in_family") is None
    zoo = [cs.flow.name for cs in spec.cases.values() if cs.flow.type == "zoo"]
    assert held >= 8 and len(set(zoo) - {"beltrami_shell"}) >= 5
    # The check can fail: trained members are recognised.
    assert family_member({"type": "uniform", "velocity": [0.5, 0, 0]}, cfg.env, families) == "uniform_currents"
    assert family_member({"type": "grid", "speed_scale": 1.1, "rotate_deg": -60}, cfg.env, families) == "wake"
    assert family_member({"type": "grid", "rotate_deg": 120}, cfg.env, families) is None
    shell = {"type": "zoo", "name": "beltrami_shell", "params": {"k0": 0.5}}  # wavelength 12.6: a trained one
    assert family_member(shell, cfg.env, families) == "fourier_modes"


def test_the_declared_training_ranges_cover_what_the_generalists_families_draw():
    """The membership test reads `training_families` from the suite config; if a family config drew beyond them,
    a zoo case could be a trained flow and still count as held out. Every member of the teacher's and the
    students' families (their experiments' flows) lies inside a declared family, and so does what every shipped
    network the students learn from was trained on (its file's recorded config): labels from a network trained on a
    zoo case would make that case a trained one."""
    declared = {
        f["name"]: f
        for f in OmegaConf.to_container(
            compose_eval("+experiment=generalization").suite.generalization.training_families
        )
    }

    def inside(lo_hi, intervals):
        return any(a <= lo_hi[0] and lo_hi[1] <= b for a, b in intervals)

    def check(member, where):
        kind = member["type"]
        if kind == "sum":
            for name, m in member["members"].items():
                check(m, f"{where}.{name}")
        elif kind == "uniform":
            assert inside(member["speed"], [declared["uniform_currents"]["ranges"]["speed"]]), where
        elif kind == "fourier":
            assert inside(member["wavelength"], [declared["fourier_modes"]["ranges"]["wavelength"]]), where
        elif kind == "wake":
            ranges = declared["wake"]["ranges"]
            assert inside(member["strength"], [ranges["strength"]]), where
            turned = [(a if a >= 0 else a + 360.0) for a in member["angle_deg"]]  # -90..90 -> 270..360 and 0..90
            for a in turned:
                assert inside([a, a], ranges["rotation_deg"]), where
        else:
            assert kind == "vortex_street" and declared["vortex_streets"]["type"] == "vortex_street", where

    for experiment in ("generalist_teacher", "generalist_student"):
        flow = OmegaConf.to_container(compose_config([f"+experiment={experiment}"], app="train").flow, resolve=True)
        assert flow["type"] == "family", experiment
        for name, member in flow["members"].items():
            check(member, f"{experiment}: flow.members.{name}")
    # What every shipped network the students learn from (and they themselves) was trained on, as its file records
    # it: the generalist networks' families, and the paper's teacher's wake as posed.
    from flownav.checkpoint import safe_torch_load
    from flownav.paths import CHECKPOINT_DIR

    files = [CHECKPOINT_DIR / "teacher.pt", *sorted(CHECKPOINT_DIR.glob("generalist_*.pt"))]
    assert len(files) >= 8
    for path in files:
        config = safe_torch_load(path)["meta"]["config"]
        flow, env = config["flow"], config["env"]
        if flow["type"] == "family":
            for name, member in flow["members"].items():
                check(member, f"{path.name}: flow.members.{name}")
        else:
            assert flow["type"] == "grid" and not flow.get("rotate_deg") and not env.get("misalignment_deg"), path
            strength = [float(flow.get("speed_scale", 1.0)) * s for s in (env.get("flow_strength") or [1.0, 1.0])]
            check({"type": "wake", "strength": strength, "angle_deg": [0.0, 0.0]}, path.name)


def test_every_zoo_case_builds_with_starts_and_targets_8_to_12_apart():
    cfg = compose_eval("+experiment=generalization")
    g = torch.Generator().manual_seed(0)
    for case, cs in cfg.suite.generalization.cases.items():
        if cs.flow.type != "zoo":
            continue
        flow = build_flow(cs.flow)
        start, target = build_task(cs.task, flow).sample(500, g)
        d = (target - start).norm(dim=-1)
        assert 8.0 <= float(d.min()) and float(d.max()) <= 12.0, case
        assert flow.bounds.contains(start).all() and flow.bounds.contains(target).all(), case


def test_the_suite_runs_tiny_and_skips_a_missing_checkpoint(tmp_path):
    overrides = [
        "+experiment=generalization",
        "max_episodes=6",
        "suite.generalization.policy_episodes.oracle=3",
        "++policies.oracle.settings={candidates: 8, horizon: 20, iterations: 1, elites: 2}",
        "suite.generalization.policies=[passive,head_to_target,oracle,generalist_student]",
        "policies.generalist_student.checkpoint=" + str(tmp_path / "absent.pt"),
        f"suite.generalization.json={tmp_path / 'generalization.json'}",
    ]
    cfg = compose_eval(*overrides)
    keep = {k: v for k, v in cfg.suite.generalization.cases.items() if k in ("still_water", "taylor_green")}
    cfg.suite.generalization.cases = keep
    r = run_suite(cfg, log=lambda *_: None, provenance={"commit": "abc123"})["generalization"]
    assert any("generalist_student" in m and "missing checkpoint" in m for m in r["missing"])
    assert set(r["results"]) == {"still_water", "taylor_green"}
    assert r["results"]["taylor_green"]["oracle"]["episodes"] == 3
    assert r["results"]["still_water"]["head_to_target"]["success_rate"] == 1.0
    row = r["summary"]["held_out"]["passive"]
    assert row["cases"] == 1 and row["compared_to_head_to_target"] == 1
    written = json.loads((tmp_path / "generalization.json").read_text())
    assert written["provenance"] == {"commit": "abc123"}  # where its numbers come from, as in results/paper.json
    assert written["results"] == json.loads(json.dumps(r["results"]))


def test_a_narrowed_entry_keeps_its_caps_and_runs(tmp_path):
    """`suite.generalization.policies=[...]` without the oracle (how docs evaluate a few policies on the zoo): the
    entry's `policy_episodes.oracle` stays in the config, unused, and the run goes on."""
    narrowed = ["max_episodes=4", "suite.generalization.policies=[passive]"]
    cfg = compose_eval("+experiment=generalization", *narrowed, f"suite.generalization.json={tmp_path / 'g.json'}")
    cfg.suite.generalization.cases = {"still_water": cfg.suite.generalization.cases.still_water}
    r = Suite(cfg, log=lambda *_: None).run("generalization", cfg.suite.generalization)
    assert set(r["results"]["still_water"]) == {"passive"}
    assert r["results"]["still_water"]["passive"]["episodes"] == 4


def test_to_an_ego_student_the_turned_wake_is_the_posed_wake_with_the_task_turned_back(capsys):
    """scripts/turned_wake_as_task.py: the zoo's wake turned by 135 degrees with the paper's task, and the wake as posed
    with the task turned by -135 degrees, are the same navigation problem in distribution for a view that turns with
    the swimmer (body-frame flow and target, the vertical; headings uniform at random in both): on the same 2,000
    starts and targets the success rates agree within sampling error (about 1.3 points), head-to-target's too."""
    from load import load_module

    script = load_module("scripts/turned_wake_as_task.py")
    suite = script.zoo_suite()
    turned, posed = script.compare(suite, "generalist_student", 135.0, 2000).values()
    assert 0.05 < turned["success_rate"] < 0.99  # a case the student neither always solves nor always fails
    assert abs(turned["success_rate"] - posed["success_rate"]) <= 0.03
    h_turned, h_posed = script.compare(suite, "head_to_target", 135.0, 2000).values()
    assert h_turned["success_rate"] > 0.05 and abs(h_turned["success_rate"] - h_posed["success_rate"]) <= 0.03
    # at another wake angle, with a policy defined on the command line (a geo view: the labellers' diagnosis)
    straight = "+policies.straight={scripted: head_to_target, obs: geo}"
    script.main(["135", "2000", "--wake-angles", "90", "--policies", "straight", "--set", straight])
    lines = capsys.readouterr().out.splitlines()
    assert [line.split(":")[0] for line in lines] == [
        "straight | the wake turned by 135, the paper's task",
        "straight | the wake turned by 90, the task turned by -45",
    ]
    rates = [float(line.split(": ")[1].split("%")[0]) for line in lines]
    assert rates[0] == pytest.approx(100 * h_turned["success_rate"]) and abs(rates[1] - rates[0]) <= 3


def test_where_episodes_leave_counts_each_face_of_the_box():
    """scripts/where_episodes_leave.py: a final position beyond a face counts for that face; head-to-target in the
    double gyre leaves through no face it could not (the flow is planar: w = 0, so nothing leaves through z)."""
    from load import load_module

    script = load_module("scripts/where_episodes_leave.py")
    final = torch.tensor([[-1.0, 1.0, 1.0], [17.0, 1.0, 1.0], [1.0, 9.0, 1.0], [1.0, 1.0, -0.5], [1.0, 9.0, 9.0]])
    counts = script.faces(final, (0.0, 0.0, 0.0), (16.0, 8.0, 8.0))
    assert counts == {"-x": 1, "+x": 1, "-y": 0, "+y": 2, "-z": 1, "+z": 1}
    r = script.leaving("double_gyre", ["head_to_target"], 200)["head_to_target"]
    assert r["episodes"] == 200 and r["faces"]["-z"] == r["faces"]["+z"] == 0
    assert r["left"] == sum(r["faces"].values())  # every episode that leaves lies beyond exactly one face
    # --set: a policy defined on the command line runs on the same episodes
    defined = ("+policies.straight={scripted: head_to_target, obs: geo}",)
    assert script.leaving("double_gyre", ["straight"], 200, defined)["straight"] == r
