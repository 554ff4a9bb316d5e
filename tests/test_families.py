"""Flow families, the family task and the privileged views of the generalist (docs/generalist.md)."""

import math

import pytest
import torch
from load import load_module
from omegaconf import OmegaConf

from flownav.builders import build_flow, build_task
from flownav.envs import NavigationEnv
from flownav.envs.observations import observation_size
from flownav.envs.tasks import REGION_1, REGION_2, FamilyTask
from flownav.errors import ConfigError
from flownav.flows import FunctionFlow, UniformFlow
from flownav.flows.base import WAKE_BOUNDS, Box, Cylinder
from flownav.flows.families import (
    FourierFamily,
    MixtureFamily,
    SumFamily,
    TransformedFamily,
    UniformFamily,
    vortex_street_family,
)
from flownav.paths import REPO_ROOT


def drawn(family, n, seed=0):
    family.allocate(n)
    family.resample(torch.arange(n), torch.Generator().manual_seed(seed))
    return family


def divergence(flow, pos, t, idx=None):
    pos = pos.clone().requires_grad_(True)
    u = flow.velocity(pos, t, idx)
    return sum(torch.autograd.grad(u[:, i].sum(), pos, retain_graph=True)[0][:, i] for i in range(3)), u


def test_fourier_modes_are_divergence_free_and_beltrami():
    f = drawn(FourierFamily(modes=6, wavelength=(2.0, 20.0), frequency=1.0), 32)
    pos, t = torch.rand(32, 3, dtype=torch.float64) * 20 - 5, torch.rand(32, dtype=torch.float64) * 50
    f.params = {k: v.double() for k, v in f.params.items()}
    div, u = divergence(f, pos, t)
    assert u.abs().max() > 0.05
    assert div.abs().max() < 1e-6  # k.a = k.b = 0 up to the float32 rounding of the drawn parameters
    # One mode alone is a Beltrami field: curl u = -|k| u (b = k/|k| x a: left-handed).
    one = FourierFamily(modes=1)
    drawn(one, 4)
    one.params = {k: v.double() for k, v in one.params.items()}
    p = pos[:4].clone().requires_grad_(True)
    u = one.velocity(p, t[:4])
    J = torch.stack([torch.autograd.grad(u[:, i].sum(), p, retain_graph=True)[0] for i in range(3)], 1)  # du_i/dx_j
    curl = torch.stack((J[:, 2, 1] - J[:, 1, 2], J[:, 0, 2] - J[:, 2, 0], J[:, 1, 0] - J[:, 0, 1]), -1)
    kmag = one.params["k"][:, 0].norm(dim=-1, keepdim=True)
    assert torch.allclose(curl, -kmag * u, atol=1e-6)


def test_fourier_rms_speed_is_the_drawn_speed():
    f = drawn(FourierFamily(modes=8, speed=(0.3, 0.9)), 3, seed=5)
    n = 100_000
    gen = torch.Generator().manual_seed(1)
    pos, t = torch.rand(n, 3, generator=gen) * 200, torch.rand(n, generator=gen) * 500
    for slot in range(3):
        u = f.velocity(pos, t, torch.full((n,), slot))
        rms = u.pow(2).sum(-1).mean().sqrt()
        assert rms == pytest.approx(float(f.params["speed"][slot]), rel=0.03)
        assert 0.3 <= float(f.params["speed"][slot]) <= 0.9


def test_rows_follow_their_slots():
    """velocity(pos[idx], t[idx], idx) is row for row the full evaluation's, for every member kind."""
    base = FunctionFlow(
        lambda p, t: torch.stack((1 + p[:, 1] * 0.1, torch.sin(p[:, 0] + t), p[:, 2] * 0), -1),
        WAKE_BOUNDS,
        1.0,
        obstacles=[Cylinder((0.0, 0.0), 0.5)],
        period=3.0,
    )
    members = [FourierFamily(), UniformFamily(), TransformedFamily([base, base])]
    families = [*members, MixtureFamily(members, [1, 1, 1]), SumFamily([FourierFamily(), UniformFamily()])]
    for family in families:
        drawn(family, 16)
        pos, t = torch.rand(16, 3) * 10, torch.rand(16) * 10
        full = family.velocity(pos, t)
        idx = torch.tensor([3, 7, 11])
        assert torch.allclose(family.velocity(pos[idx], t[idx], idx), full[idx]), type(family).__name__
        # The family taken for those rows (the oracle's rollouts) gives exactly what the slots give.
        taken = family.take(idx)
        assert torch.equal(taken.velocity(pos[idx], t[idx]), family.velocity(pos[idx], t[idx], idx))
        assert torch.equal(taken.in_obstacle(pos[idx]), family.in_obstacle(pos[idx], idx))
        with pytest.raises(ValueError, match="one row per env slot"):
            family.velocity(pos[idx], t[idx])


def test_two_swimmers_of_one_batch_feel_different_flows_at_the_same_place_and_step():
    flow = build_flow(OmegaConf.load("conf/flow/family_fourier.yaml"))
    env = NavigationEnv(flow, task=FamilyTask(WAKE_BOUNDS), num_envs=4, views=("geo",), seed=0)
    td = env.reset()
    td["action"] = env.action_spec.rand()
    env.step(td)
    same = torch.tensor([[10.0, 0.0, 5.0]]).expand(4, 3)
    u = env._flow_at(same, env.t0 + env.time)
    assert (env.time == env.time[0]).all()
    assert (u[0] - u[1]).norm() > 1e-3 and (u[2] - u[3]).norm() > 1e-3
    # A reset of one slot draws a new flow for it and leaves the others' flows alone.
    before = env._flow_at(same, env.t0 + env.time)
    env.reset(td.set("_reset", torch.tensor([[True], [False], [False], [False]])))
    after = env._flow_at(same, env.t0 + env.time)
    assert (after[0] - before[0]).norm() > 1e-3 and torch.equal(after[1:], before[1:])


def test_the_zero_current_member_is_still_water():
    flow = UniformFamily(speed=(0.5, 1.0), still_share=1.0)
    env = NavigationEnv(
        flow,
        task=FamilyTask(WAKE_BOUNDS, swim_speed=(0.2, 0.2), full_speed_share=0.0),
        num_envs=64,
        views=("geo",),
        seed=1,
    )
    td = env.reset()
    start = td["position"].clone()
    td["action"] = torch.tensor([1.0, 0.0, 0.0]).expand(64, 3)
    nxt = env.step(td)["next"]
    assert torch.equal(env.flow_vel, torch.zeros(64, 3))
    # The swimmer moves by its own swim velocity only: speed 0.2 for one step of dt.
    step = (nxt["position"] - start).norm(dim=-1)
    assert torch.allclose(step, torch.full((64,), 0.2 * env.dt), atol=1e-6)
    # Uniform currents have the drawn strength, in every direction.
    cur = drawn(UniformFamily(speed=(0.5, 1.0)), 2000)
    s = cur.params["velocity"].norm(dim=-1)
    assert s.min() >= 0.5 and s.max() <= 1.0
    assert cur.params["velocity"].mean(0).norm() < 0.05


def test_a_share_of_the_currents_runs_vertically_both_ways():
    velocity = drawn(UniformFamily(speed=(0.5, 1.0), vertical_share=0.5), 4000).params["velocity"]
    vertical = velocity[:, :2].abs().sum(-1) == 0
    assert 0.45 < vertical.float().mean() < 0.55
    assert 0.45 < (velocity[vertical, 2] > 0).float().mean() < 0.55
    assert velocity[vertical, 2].abs().min() >= 0.5
    # The option only turns those draws: the others keep the directions of the family without it.
    plain = drawn(UniformFamily(speed=(0.5, 1.0)), 4000).params["velocity"]
    unit = torch.nn.functional.normalize
    assert torch.allclose(unit(velocity[~vertical], dim=-1), unit(plain[~vertical], dim=-1), atol=1e-6)
    with pytest.raises(ValueError, match=r"vertical_share is a fraction in \[0, 1\], got 1.5"):
        UniformFamily(vertical_share=1.5)


def test_transformed_family_rotates_scales_and_moves_obstacles():
    base = UniformFlow((1.0, 0.0, 0.0))
    base.obstacles = (Cylinder((0.0, 0.0), 0.5),)
    fam = drawn(TransformedFamily([base], angle_deg=(90, 90), strength=(0.5, 0.5), background=(0, 0), center=(9, 0)), 2)
    u = fam.velocity(torch.tensor([[3.0, 1.0, 2.0], [15.0, -3.0, 0.0]]), torch.zeros(2))
    assert torch.allclose(u, torch.tensor([[0.0, 0.5, 0.0]] * 2), atol=1e-6)
    # The cylinder at (0, 0) turned by 90 degrees about (9, 0) sits at (9, -9).
    inside = fam.in_obstacle(torch.tensor([[9.0, -9.0, 1.0], [0.0, 0.0, 1.0]]))
    assert inside.tolist() == [True, False]
    bg = drawn(TransformedFamily([base], angle_deg=(0, 0), strength=(0, 0), background=(0.3, 0.3)), 500)
    v = bg.velocity(torch.zeros(500, 3), torch.zeros(500))
    assert torch.allclose(v.norm(dim=-1), torch.full((500,), 0.3)) and v[:, 2].abs().max() == 0


def test_vortex_street_family_draws_a_bank_of_different_streets():
    fam = vortex_street_family(variants=2, seed=0)
    a, b = fam.bases
    assert a.gamma != b.gamma and a.T != b.T
    drawn(fam, 8)
    assert fam.velocity(torch.rand(8, 3) * 5 + 5, torch.zeros(8)).isfinite().all()


def test_mixture_picks_members_by_weight():
    slow, fast = UniformFamily(speed=(0.1, 0.1)), UniformFamily(speed=(0.9, 0.9))
    mix = drawn(MixtureFamily([slow, fast], [1.0, 3.0]), 4000)
    speed = mix.velocity(torch.zeros(4000, 3), torch.zeros(4000)).norm(dim=-1)
    assert torch.allclose(speed[mix.params["member"] == 0], torch.tensor(0.1))
    assert torch.allclose(speed[mix.params["member"] == 1], torch.tensor(0.9))
    assert (mix.params["member"] == 1).float().mean() == pytest.approx(0.75, abs=0.03)


def test_family_task_distances_directions_and_regions():
    task = FamilyTask(WAKE_BOUNDS, distance=(4.0, 9.0), margin=1.0, regions_share=0.3)
    start, target = task.sample(20_000, torch.Generator().manual_seed(0))
    in_regions = REGION_1.contains(start) & REGION_2.contains(target)
    assert in_regions.float().mean() == pytest.approx(0.3, abs=0.02)  # anywhere-pairs rarely land there
    d = (target - start)[~in_regions]
    assert d.norm(dim=-1).min() >= 4.0 - 1e-5 and d.norm(dim=-1).max() <= 9.0 + 1e-5
    unit = d / d.norm(dim=-1, keepdim=True)
    assert (unit[:, 2] > 0.9).any() and (unit[:, 2] < -0.9).any() and (unit[:, 0] < -0.9).any()
    assert task.box.contains(start[~in_regions]).all() and task.box.contains(target[~in_regions]).all()
    with pytest.raises(ValueError, match="distance"):
        FamilyTask(WAKE_BOUNDS, distance=(30.0, 40.0))


def test_posed_wake_any_start_share_moves_only_the_posed_wakes_starts():
    """In the wake as posed, the paper's target with a start anywhere in that share; elsewhere nothing changes."""
    task = FamilyTask(WAKE_BOUNDS, regions_share=0.0, posed_wake_regions_share=1.0, posed_wake_any_start_share=0.4)
    n = 20_000
    posed = torch.arange(n) % 2 == 0
    start, target = task.sample(n, torch.Generator().manual_seed(0), posed=posed)
    assert REGION_2.contains(target[posed]).all()
    in_region_1 = REGION_1.contains(start[posed])
    assert (~in_region_1).float().mean() == pytest.approx(0.4, abs=0.02)  # Region 1 is a small share of the box
    assert task.box.contains(start[posed]).all()
    same = FamilyTask(WAKE_BOUNDS, regions_share=0.0, posed_wake_regions_share=1.0)
    plain = same.sample(n, torch.Generator().manual_seed(0), posed=posed)
    assert torch.equal(plain[0][~posed], start[~posed]) and torch.equal(plain[1], target)
    with pytest.raises(ValueError, match="posed_wake_any_start_share is a fraction"):
        FamilyTask(WAKE_BOUNDS, posed_wake_any_start_share=1.5)


def test_posed_wake_any_start_box_bounds_the_far_starts():
    upstream = Box((-3.0, -6.0, -4.0), (4.0, 6.0, 14.0))
    task = FamilyTask(
        WAKE_BOUNDS,
        regions_share=0.0,
        posed_wake_regions_share=1.0,
        posed_wake_any_start_share=0.5,
        posed_wake_any_start_box=upstream,
    )
    posed = torch.ones(4000, dtype=torch.bool)
    start, target = task.sample(4000, torch.Generator().manual_seed(1), posed=posed)
    far = ~REGION_1.contains(start)
    assert far.float().mean() == pytest.approx(0.5, abs=0.03)
    assert upstream.contains(start[far]).all() and REGION_2.contains(target).all()


def test_swim_speed_factor_range_and_the_env_applies_it():
    task = FamilyTask(WAKE_BOUNDS, swim_speed=(0.05, 1.0), full_speed_share=0.25)
    s = task.swim_speed(40_000, torch.Generator().manual_seed(0))
    assert s.min() >= 0.05 - 1e-6 and s.max() <= 1.0 + 1e-6
    assert (s == 1).float().mean() == pytest.approx(0.25, abs=0.01)
    drawn_ = torch.log(s[s < 1])
    assert drawn_.median() == pytest.approx(0.5 * math.log(0.05), abs=0.05)  # log-uniform: median at the middle
    env = NavigationEnv(
        UniformFamily(speed=(0, 0)),
        task=task,
        num_envs=256,
        views=("geo_priv", "ego_mem", "ego_mem_speed"),
        swim_speed_scale=2.0,
        seed=0,
    )
    td = env.reset()
    assert env.swim_scale.min() >= 2.0 * 0.05 - 1e-6 and env.swim_scale.max() <= 2.0 + 1e-6
    assert (env.swim_scale == 2.0).any() and (env.swim_scale < 1.0).any()
    assert torch.allclose(td["geo_priv"][:, 21], env.u_max * env.swim_scale)
    # The ego student that knows its own propulsion: ego_mem, then the same full swim speed.
    assert torch.equal(td["ego_mem_speed"][:, :-1], td["ego_mem"])
    assert torch.equal(td["ego_mem_speed"][:, -1], td["geo_priv"][:, 21])
    start = td["position"].clone()
    td["action"] = torch.tensor([1.0, 0.0, 0.0]).expand(256, 3)
    moved = (env.step(td)["next", "position"] - start).norm(dim=-1)
    assert torch.allclose(moved, env.swim_scale * env.dt, atol=1e-6)


def test_privileged_views_on_a_linear_flow():
    """u = M x + c: the gradient in geo_priv is M (forward differences are exact), the rest as documented."""
    M = torch.tensor([[0.1, -0.2, 0.05], [0.3, 0.0, -0.1], [0.02, 0.04, -0.1]])
    c = torch.tensor([0.4, -0.1, 0.2])
    flow = FunctionFlow(lambda p, t: p @ M.T + c, WAKE_BOUNDS, 2.0)
    env = NavigationEnv(flow, num_envs=8, views=("geo_priv", "geo_priv_critic", "geo_sincos"), time_limit=10.0, seed=0)
    td = env.reset()
    td["action"] = env.action_spec.rand()
    td = env.step(td)["next"]
    priv, critic = td["geo_priv"], td["geo_priv_critic"]
    assert priv.shape[-1] == observation_size("geo_priv") == 23 and critic.shape[-1] == 27
    assert torch.equal(priv[:, :9], td["geo_sincos"])
    u = td["position"] @ M.T + c
    assert torch.allclose(priv[:, 9:12], u, atol=1e-5)
    assert torch.allclose(priv[:, 12:21].view(8, 3, 3), M.expand(8, 3, 3), atol=2e-3)
    assert torch.allclose(priv[:, 21], torch.ones(8))  # swim speed u_max x 1
    assert torch.allclose(priv[:, 22], torch.log(1.0 / (u.norm(dim=-1) + 0.05)), atol=1e-5)
    assert torch.equal(critic[:, :23], priv)
    assert torch.allclose(critic[:, 23], torch.full((8,), 1 - 1 / 50))  # one of 50 steps done
    assert torch.allclose(critic[:, 24:], td["target"] @ M.T + c, atol=1e-5)


def test_the_view_around_reads_the_flow_at_its_probe_points():
    """geo_priv_around = geo_priv and the flow at AROUND_OFFSETS from the swimmer: exact on a linear flow, and in a
    family each swimmer's own flow at its own points (after steps and a partial reset)."""
    from flownav.envs.observations import AROUND_OFFSETS

    M = torch.tensor([[0.1, -0.2, 0.05], [0.3, 0.0, -0.1], [0.02, 0.04, -0.1]])
    c = torch.tensor([0.4, -0.1, 0.2])
    flow = FunctionFlow(lambda p, t: p @ M.T + c, WAKE_BOUNDS, 2.0)
    env = NavigationEnv(flow, num_envs=8, views=("geo_priv_around", "geo_priv"), time_limit=10.0, seed=0)
    td = env.reset()
    td["action"] = env.action_spec.rand()
    td = env.step(td)["next"]
    around, offsets = td["geo_priv_around"], torch.tensor(AROUND_OFFSETS)
    assert around.shape[-1] == observation_size("geo_priv_around") == 23 + 36 and len(AROUND_OFFSETS) == 12
    assert torch.equal(around[:, :23], td["geo_priv"])
    expected = (td["position"][:, None] + offsets) @ M.T + c  # [8, 12, 3]
    assert torch.allclose(around[:, 23:].view(8, 12, 3), expected, atol=1e-5)
    assert offsets.abs().sum(-1).tolist() == [1.0] * 6 + [2.0] * 6
    env = NavigationEnv(FourierFamily(), num_envs=4, views=("geo_priv_around",), time_limit=10.0, seed=0)
    td = env.reset()
    for _ in range(2):
        td["action"] = env.action_spec.rand()
        td = env.step(td)["next"]
    td = env.reset(td.clone().set("_reset", torch.tensor([0, 1, 0, 0], dtype=torch.bool)[:, None]))
    s = env.state
    for slot in range(4):
        points = s.pos[slot] + offsets
        idx, t = torch.full((12,), slot), (s.t0[slot] + s.time[slot]).expand(12)
        got = td["geo_priv_around"][slot, 23:].view(12, 3)
        assert torch.allclose(got, env.flow.velocity(points, t, idx), atol=1e-6)


def test_privileged_look_up_in_a_family_after_steps_and_a_partial_reset():
    """The flow, its gradient (forward differences of GRADIENT_STEP) and the flow at the target that the privileged
    views read come from one look-up of 5 points per swimmer: the same numbers as separate look-ups of each slot's
    own flow, for slots that stepped and for slots just reset."""
    from flownav.envs.core import GRADIENT_STEP

    env = NavigationEnv(FourierFamily(), num_envs=6, views=("geo_priv_critic",), time_limit=10.0, seed=0)
    td = env.reset()
    for _ in range(3):
        td["action"] = env.action_spec.rand()
        td = env.step(td)["next"]
    env.reset(td.clone().set("_reset", torch.tensor([0, 1, 0, 0, 1, 0], dtype=torch.bool)[:, None]))
    s, slots = env.state, torch.arange(6)
    t = s.t0 + s.time
    u = env.flow.velocity(s.pos, t, slots)
    shifted = [env.flow.velocity(s.pos + GRADIENT_STEP * e, t, slots) for e in torch.eye(3)]
    grad = torch.stack([(v - u) / GRADIENT_STEP for v in shifted], -1)  # [slot, i, j]: du_i/dx_j
    assert s.time[1] == 0 and s.time[0] > 0
    assert torch.allclose(s.flow_vel, u, atol=1e-6)
    assert torch.allclose(s.flow_grad, grad, atol=1e-4)
    assert torch.allclose(s.target_flow, env.flow.velocity(s.target, t, slots), atol=1e-6)


def test_family_configs_build_and_bad_members_fail_with_the_key():
    for name in ("family_fourier", "family_current", "family_vortex_street"):
        flow = build_flow(OmegaConf.load(f"conf/flow/{name}.yaml"))
        drawn(flow, 4)
        assert flow.velocity(torch.rand(4, 3), torch.zeros(4)).isfinite().all()
    task = build_task(OmegaConf.load("conf/task/family.yaml"), flow)
    assert isinstance(task, FamilyTask) and task.regions_share == 0.25
    bad = {"type": "family", "members": {"f": {"type": "fourierr"}}}
    with pytest.raises(ConfigError, match=r"flow.members.f.type is 'fourierr'"):
        build_flow(bad)
    bad = {"type": "family", "members": {"f": {"type": "fourier", "speed": [1.0, 0.5]}}}
    with pytest.raises(ConfigError, match=r"flow.members.f \(type: fourier\): speed must be"):
        build_flow(bad)
    with pytest.raises(ValueError, match="misalignment_deg"):
        NavigationEnv(FourierFamily(), num_envs=2, views=("geo",), misalignment_deg=30)


def test_a_periodic_fourier_family_is_periodic_per_swimmer_and_divergence_free():
    flow = build_flow(OmegaConf.load("conf/flow/family_fourier_periodic.yaml"))
    assert flow.periodic_axes == (1, 2)
    n = 64
    drawn(flow, n, seed=3)
    k = flow.params["k"]
    assert torch.allclose(k[..., 1:], k[..., 1:].round(), atol=1e-5)  # the box is 2 pi wide in y and z
    assert not torch.allclose(k[..., 0], k[..., 0].round(), atol=1e-3)  # x is bounded: continuous
    gen = torch.Generator().manual_seed(0)
    pos, t = torch.rand(n, 3, generator=gen) * 6 - 3, torch.rand(n, generator=gen) * 40
    u = flow.velocity(pos, t)
    for shift in ([0.0, 2 * math.pi, 0.0], [0.0, 0.0, -2 * math.pi], [0.0, 4 * math.pi, 2 * math.pi]):
        assert torch.allclose(flow.velocity(pos + torch.tensor(shift), t), u, atol=1e-4)
    assert not torch.allclose(flow.velocity(pos + torch.tensor([2 * math.pi, 0.0, 0.0]), t), u, atol=1e-2)
    flow.params = {key: v.double() for key, v in flow.params.items()}
    div, u = divergence(flow, pos.double(), t.double())
    assert u.abs().max() > 0.1 and div.abs().max() < 1e-5
    # Off the periodic axes the draw is a plain family's: the same k_x and phases from the same seed.
    free, lattice = drawn(FourierFamily(), 8, seed=1), drawn(FourierFamily(periodic_axes=(1, 2)), 8, seed=1)
    assert torch.equal(free.params["k"][..., 0], lattice.params["k"][..., 0])
    assert torch.equal(free.params["phase"], lattice.params["phase"])


def test_a_sum_member_refuses_a_key_it_would_ignore():
    """A sum takes only its parts; a part of a sum has no weight (every part is added to every swimmer's flow)."""
    mix = OmegaConf.to_container(OmegaConf.load("conf/flow/family_mix.yaml"))
    part = mix["members"]["fourier_on_current"]
    with pytest.raises(ConfigError, match=r"^flow.members.fourier_on_current \(type: sum\) has an unknown key 'foo'"):
        build_flow(mix | {"members": {"fourier_on_current": part | {"foo": 1}}})
    weighted = part | {"members": part["members"] | {"current": part["members"]["current"] | {"weight": 3}}}
    with pytest.raises(ConfigError, match=r"^flow.members.fourier_on_current.members.current.weight: a part of a sum"):
        build_flow(mix | {"members": {"fourier_on_current": weighted}})


def test_a_periodic_family_refuses_a_member_that_is_not_periodic():
    cfg = OmegaConf.load("conf/flow/family_fourier_periodic.yaml")
    cfg.members = {"current": {"type": "uniform", "speed": [0.0, 1.0]}, "street": {"type": "vortex_street"}}
    with pytest.raises(ConfigError, match="flow.periodic_axes: the flow is not periodic over its box on axis y"):
        build_flow(cfg)
    cfg.members = {"current": {"type": "uniform", "speed": [0.0, 1.0]}}  # any box is a period of a uniform flow
    assert build_flow(cfg).periodic_axes == (1, 2)
    # However rarely a mixture draws it, a member that is not periodic is checked and refused; one never drawn is not.
    fourier = OmegaConf.load("conf/flow/family_fourier_periodic.yaml").members.fourier
    cfg.members = {"fourier": fourier, "street": {"type": "vortex_street", "weight": 1e-6}}
    with pytest.raises(ConfigError, match="flow.periodic_axes: the flow is not periodic over its box on axis y"):
        build_flow(cfg)
    cfg.members.street.weight = 0.0
    assert build_flow(cfg).periodic_axes == (1, 2)


def test_a_generalist_student_imitates_a_privileged_teacher(tmp_path):
    """DAgger takes the teacher's privileged view from its checkpoint and reads it from the same env."""
    from hydra import compose, initialize_config_dir

    import train
    from flownav.agents.networks import DeterministicPolicy
    from flownav.checkpoint import load_policy, save_policy_checkpoint
    from flownav.envs.navigation import DPSI_MAX, DTHETA_MAX

    low, high = [0.0, -DTHETA_MAX, -DPSI_MAX], [1.0, DTHETA_MAX, DPSI_MAX]
    teacher = tmp_path / "teacher.pt"
    save_policy_checkpoint(teacher, DeterministicPolicy(23, low, high, hidden=(8,)), "geo_priv", "teacher")
    tiny = ["flow=family_current", "algo.iterations=1", "algo.num_envs=16", "algo.steps_per_iteration=10",
            "algo.updates_per_iteration=2", "algo.batch_size=32", "algo.hidden=[8]", "algo.final_eval_episodes=0",
            "logger=csv", "logger.progress=false", "threads=1", f"teacher_checkpoint={teacher}"]  # fmt: skip
    with initialize_config_dir(config_dir=str(REPO_ROOT / "conf"), version_base="1.3"):
        cfg = compose("config", overrides=["+experiment=generalist_student", *tiny])
    final = train.run(cfg, tmp_path / "run")
    assert final["frames"] == 160
    _, payload = load_policy(tmp_path / "run" / "checkpoints" / "last.pt", expect_obs="ego_mem_grad")
    assert payload["meta"]["teacher_checkpoint"] == str(teacher)
    assert payload["meta"]["scene_expert"] == "checkpoints/teacher.pt"  # the routed teacher's expert
    assert payload["meta"]["scene_reverse_expert"] == "checkpoints/generalist_reverse_expert.pt"  # the crossing back


def test_family_benchmark_code_path_runs():
    bench = load_module("benchmarks/family_throughput.py")
    step = bench.make_stepper("family_fourier", ("geo_priv", "geo_priv_critic"), 8)
    assert bench.window_rate(step, 8, 0.01) > 0
    step = bench.make_stepper("family_fourier_periodic", ("geo_priv_around", "geo_priv_critic"), 8)  # the ABC task
    assert bench.window_rate(step, 8, 0.01) > 0


def test_a_periodic_evaluation_figure_of_a_family_draws_the_recorded_paths():
    """A family has one flow per swimmer, so the training dashboard's figure draws the paths without a field."""
    from flownav.evaluation.protocol import EvalSpec, evaluate
    from flownav.evaluation.scripted import HeadToTarget
    from flownav.viz.dashboard import eval_trajectories_figure

    flow = build_flow(OmegaConf.create({"type": "family", "members": {"c": {"type": "uniform", "speed": [0.0, 0.5]}}}))
    task = FamilyTask(WAKE_BOUNDS, distance=(4.0, 6.0))
    from flownav.builders import compose_config

    env_cfg = compose_config(["env.time_limit=10.0"]).env
    ev = evaluate(HeadToTarget(), "geo", EvalSpec(flow, task, env_cfg, 8), record=3)
    fig = eval_trajectories_figure(ev.episodes.trajectories, flow)
    paths = [line for line in fig.axes[0].lines if len(line.get_xdata()) > 1]
    assert len(paths) == 3 and len(fig.axes) == 1  # one path per recorded episode, no colorbar


def test_turned_scaled_shifted_summed_and_mixed_members_stay_divergence_free():
    """What the families build from divergence-free flows (a turn about z, a strength, a time shift, a uniform
    background current; sums; mixtures) is divergence-free, swimmer by swimmer: each is linear in the flows, and a
    turn about z of a divergence-free field is one."""
    A, B, C = 1.0, 0.7, 0.4

    def abc(p, t):  # the ABC flow made time-dependent: div u = 0 at every time
        w = 1 + 0.3 * torch.sin(t)
        x, y, z = p.unbind(-1)
        return torch.stack((A * torch.sin(z) + C * torch.cos(y), B * torch.sin(x) + A * torch.cos(z) * w,
                            C * torch.sin(y) + B * torch.cos(x)), -1)  # fmt: skip

    base = FunctionFlow(abc, WAKE_BOUNDS, 2.0, period=2 * math.pi)
    turned = TransformedFamily([base], angle_deg=(-180.0, 180.0), strength=(0.2, 2.0), background=(0.0, 0.5))
    summed = SumFamily([TransformedFamily([base]), FourierFamily(modes=4), UniformFamily()], WAKE_BOUNDS)
    mixed = MixtureFamily([summed, TransformedFamily([base])], [1.0, 1.0], WAKE_BOUNDS)
    n = 64
    gen = torch.Generator().manual_seed(0)
    pos, t = torch.rand(n, 3, generator=gen) * 14 - 4, torch.rand(n, generator=gen) * 30
    for family in (turned, summed, mixed):
        drawn(family, n, seed=2)
        div, u = divergence(family, pos, t)
        assert u.abs().max() > 0.5
        assert div.abs().max() < 1e-5, type(family).__name__  # float32: the derivatives are O(1)
    angles = torch.atan2(turned.params["sin"], turned.params["cos"])
    assert angles.max() - angles.min() > 3  # the members differ: turned every way
