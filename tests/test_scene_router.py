"""The scene-routed teacher of the generalist students: the simulator's paper-scene flag and the routing."""

import math

import pytest
import torch
from omegaconf import OmegaConf

from flownav.agents.flow_compensating import FlowCompensating
from flownav.agents.networks import DeterministicPolicy
from flownav.agents.scene_router import CAPPED_MIN_PROGRESS, SceneRoutedTeacher, scene_routed
from flownav.builders import build_task
from flownav.envs import NavigationEnv
from flownav.envs.core import SCENE_REVERSE, UPSTREAM_X
from flownav.envs.observations import GEO_PRIV_FLOW, observation_size, turn_geo_priv
from flownav.envs.tasks import REGION_1, REGION_2, FamilyTask, RegionTask
from flownav.errors import CheckpointError
from flownav.flows.base import WAKE_BOUNDS
from flownav.flows.families import FourierFamily, MixtureFamily, SumFamily, TransformedFamily, UniformFamily
from flownav.flows.synthetic import synthetic_wake
from flownav.flows.transforms import RotatedFlow
from flownav.paths import REPO_ROOT

LOW, HIGH = [0.0, -0.785, -1.571], [1.0, 0.785, 1.571]


def scene_flags(flow, task=None, n=256, **env_kw):
    env = NavigationEnv(flow, task or RegionTask(), num_envs=n, views=("geo_priv_scene",), seed=3, **env_kw)
    obs = env.reset()["geo_priv_scene"]
    return env, obs[:, -1]


def test_paper_scene_is_the_unturned_wake_at_full_strength_and_speed():
    wake = synthetic_wake()
    _, flags = scene_flags(wake)
    assert flags.eq(1).all()  # the paper's task as posed
    assert scene_flags(wake, misalignment_deg=30.0)[1].eq(0).all()  # a turned scene is another scene
    assert scene_flags(wake, swim_speed_scale=0.5)[1].eq(0).all()  # a weaker swimmer
    env, flags = scene_flags(wake, flow_strength=(0.0, 1.0), flow_strength_full=0.5)
    full = env.state.strength == 1
    assert 0 < full.sum() < full.numel() and torch.equal(flags.bool(), full)


def test_paper_scene_in_a_family_marks_only_the_posed_wake_member_with_the_papers_task():
    posed = TransformedFamily([synthetic_wake()], angle_deg=(0, 0), strength=(1, 1), background=(0, 0))
    turned = TransformedFamily([synthetic_wake()], angle_deg=(10, 80), strength=(1, 1), background=(0, 0))
    flow = MixtureFamily([posed, turned, UniformFamily()], [1.0, 1.0, 1.0], WAKE_BOUNDS)
    task = FamilyTask(WAKE_BOUNDS, regions_share=0.5, full_speed_share=0.5)
    env, flags = scene_flags(flow, task, n=2048)
    member = env.flow.params["member"]
    papers = (member == 0) & (env.state.swim_scale == 1) & REGION_2.contains(env.state.target)
    assert 100 < papers.sum() < 2048 and torch.equal((flags >= 1) & (flags <= 4), papers)
    # any other task of a full-speed swimmer in the posed wake is 7, in the turned wake 5 but the paper's regions
    # there 9; a current's are 6
    full = env.state.swim_scale == 1
    posed_other, turned = (member == 0) & ~papers & full, (member == 1) & full
    regions = REGION_1.contains(env.state.start) & REGION_2.contains(env.state.target)
    assert 100 < posed_other.sum() and 100 < (turned & ~regions).sum() and 100 < (turned & regions).sum()
    assert torch.equal(flags == 7, posed_other)
    assert torch.equal(flags == 5, turned & ~regions) and torch.equal(flags == 9, turned & regions)
    assert torch.equal(flags == 6, member == 2)
    assert torch.equal(flags == 0, (member < 2) & ~full)  # a weaker swimmer in a wake: none
    # geo_priv_scene is geo_priv plus the flow's turn and the flag
    env = NavigationEnv(flow, task, num_envs=64, views=("geo_priv", "geo_priv_scene"), seed=1)
    both = env.reset()
    assert observation_size("geo_priv_scene") == observation_size("geo_priv") + 2
    assert torch.equal(both["geo_priv_scene"][:, :-2], both["geo_priv"])
    member = env.flow.params["member"]
    turn = torch.rad2deg(both["geo_priv_scene"][:, -2])
    assert turn[member != 1].eq(0).all() and (turn[member == 1] >= 10 - 1e-4).all() and turn.max() <= 80 + 1e-4


class Constant(torch.nn.Module):
    """A policy that returns one action whatever it reads (and checks how much it reads)."""

    def __init__(self, action, size):
        super().__init__()
        self.action, self.size = torch.tensor(action), size

    def forward(self, obs):
        assert obs.shape[1] == self.size
        return self.action.expand(obs.shape[0], 3)


def test_the_routed_teacher_hands_the_flagged_rows_to_the_expert():
    generalist, expert = Constant([0.1, 0.2, 0.3], 23), Constant([0.9, -0.5, 0.0], 9)
    obs = torch.randn(8, 25)
    obs[:, -1] = torch.tensor([1.0, 0.0, 1.0, 0.0, 0.0, 1.0, 2.0, 3.0])
    out = SceneRoutedTeacher(generalist, expert)(obs)
    assert torch.equal(out[obs[:, -1] == 1], torch.tensor([[0.9, -0.5, 0.0]]).expand(3, 3))
    # code 3 (the crossing the other way) without its expert: the generalist
    assert torch.equal(out[(obs[:, -1] == 0) | (obs[:, -1] == 3)], torch.tensor([[0.1, 0.2, 0.3]]).expand(4, 3))
    # code 2 (the paper's scene from upstream of its regions): the flow-compensating expert
    assert torch.equal(out[6], FlowCompensating()(obs[6:7, :-2])[0])
    with_reverse = SceneRoutedTeacher(generalist, expert, reverse=Constant([0.5, 0.0, -0.1], 9))(obs)
    assert torch.equal(with_reverse[7], torch.tensor([0.5, 0.0, -0.1])) and torch.equal(with_reverse[:7], out[:7])


def test_the_papers_target_from_elsewhere_goes_to_the_away_expert_or_else_the_papers_teacher():
    generalist, expert = Constant([0.1, 0.2, 0.3], 23), Constant([0.9, -0.5, 0.0], 9)
    obs = torch.randn(5, 25)
    obs[:, -1] = torch.tensor([4.0, 1.0, 0.0, 4.0, 2.0])
    plain = SceneRoutedTeacher(generalist, expert)(obs)
    assert torch.equal(plain[[0, 1, 3]], torch.tensor([[0.9, -0.5, 0.0]]).expand(3, 3))
    away = SceneRoutedTeacher(generalist, expert, away=Constant([0.4, 0.1, 0.2], 23))(obs)  # reads geo_priv
    assert torch.equal(away[[0, 3]], torch.tensor([[0.4, 0.1, 0.2]]).expand(2, 3))
    assert torch.equal(away[[1, 2, 4]], plain[[1, 2, 4]])


def test_other_tasks_in_the_posed_wake_go_to_the_posed_expert_or_else_the_wake_expert():
    generalist, expert = Constant([0.1, 0.2, 0.3], 23), Constant([0.9, -0.5, 0.0], 9)
    wake, posed = Constant([0.4, 0.1, 0.2], 23), Constant([-0.3, 0.6, -0.7], 23)
    obs = torch.randn(4, 25)
    obs[:, -1] = torch.tensor([7.0, 5.0, 0.0, 7.0])
    plain = SceneRoutedTeacher(generalist, expert)(obs)
    assert torch.equal(plain, torch.tensor([[0.1, 0.2, 0.3]]).expand(4, 3))  # neither given: the generalist
    with_wake = SceneRoutedTeacher(generalist, expert, wake=wake)(obs)
    assert torch.equal(with_wake[[0, 1, 3]], torch.tensor([[0.4, 0.1, 0.2]]).expand(3, 3))
    both = SceneRoutedTeacher(generalist, expert, wake=wake, posed=posed)(obs)
    assert torch.equal(both[[0, 3]], torch.tensor([[-0.3, 0.6, -0.7]]).expand(2, 3))
    assert torch.equal(both[[1, 2]], with_wake[[1, 2]])


def test_an_episode_that_starts_upstream_in_the_papers_scene_is_coded_2_all_along():
    flow = posed_and_turned_wakes()
    # as a training config sets it (conf/task/family.yaml plus overrides), through the schema and the builder
    cfg = OmegaConf.load(REPO_ROOT / "conf/task/family.yaml")
    cfg.regions_share, cfg.full_speed_share = 0.0, 1.0
    cfg.posed_wake_regions_share, cfg.posed_wake_any_start_share = 1.0, 0.5
    cfg.posed_wake_any_start_box = [[-3.0, -6.0, 3.0], [UPSTREAM_X, 6.0, 7.0]]
    task = build_task(cfg, flow)
    env = NavigationEnv(flow, task, num_envs=512, views=("geo_priv_scene",), seed=4)
    td = env.reset()
    in_posed = env.flow.params["member"] == 0
    from_upstream = in_posed & (env.state.pos[:, 0] < UPSTREAM_X)
    assert 50 < from_upstream.sum() < 200
    expected = torch.where(from_upstream, 2.0, torch.where(in_posed, 1.0, 5.0))  # the turned wake: 5
    assert REGION_1.contains(env.state.pos[in_posed & ~from_upstream]).all()  # the others start in Region 1
    assert torch.equal(td["geo_priv_scene"][:, -1], expected)
    for _ in range(10):  # the code follows the start, not the swimmer: swimming downstream keeps it
        td["action"] = torch.tensor([1.0, 0.0, 0.0]).expand(512, 3)
        td = env.step(td)["next"]
    running = ~td["done"].reshape(-1)
    assert torch.equal(td["geo_priv_scene"][running, -1], expected[running])


def test_the_papers_target_from_a_start_beyond_upstream_and_outside_region_1_is_coded_4():
    cfg = OmegaConf.load(REPO_ROOT / "conf/task/family.yaml")
    cfg.regions_share, cfg.full_speed_share = 0.0, 1.0
    cfg.posed_wake_regions_share, cfg.posed_wake_any_start_share = 1.0, 0.5  # the box: the whole shrunk domain
    flow = posed_and_turned_wakes()
    env = NavigationEnv(flow, build_task(cfg, flow), num_envs=1024, views=("geo_priv_scene",), seed=6)
    code, s = env.reset()["geo_priv_scene"][:, -1], env.state
    in_posed, start = env.flow.params["member"] == 0, s.pos
    upstream, region_1 = start[:, 0] < UPSTREAM_X, REGION_1.contains(start)
    away = in_posed & ~upstream & ~region_1
    assert 100 < away.sum() and 30 < (in_posed & upstream).sum()
    assert torch.equal(code == 4, away) and torch.equal(code == 2, in_posed & upstream)
    assert torch.equal(code == 1, in_posed & region_1) and torch.equal(code == 5, ~in_posed)


def test_the_crossing_from_region_2_to_region_1_in_the_posed_wake_is_coded_3():
    task = FamilyTask(WAKE_BOUNDS, regions_share=0.0, posed_wake_regions_share=1.0, posed_wake_reverse_share=0.5)
    env = NavigationEnv(posed_and_turned_wakes(), task, num_envs=512, views=("geo_priv_scene",), seed=5)
    code = env.reset()["geo_priv_scene"][:, -1]
    in_posed, s = env.flow.params["member"] == 0, env.state
    back = REGION_2.contains(s.pos) & REGION_1.contains(s.target)
    assert torch.equal(back, in_posed & ~REGION_1.contains(s.pos))  # the posed wake's crossings, either way
    assert 0.4 < back[in_posed].float().mean() < 0.6
    full = s.swim_scale == 1
    assert torch.equal(code == 3, back & full) and torch.equal(code == 1, in_posed & ~back & full)


def test_a_wake_on_a_current_is_a_wake_scene_and_currents_alone_are_the_current_scene():
    turned = TransformedFamily([synthetic_wake()], angle_deg=(10, 80), strength=(1, 1), background=(0, 0))
    on_current = SumFamily([turned, UniformFamily()])
    env, flags = scene_flags(on_current, FamilyTask(WAKE_BOUNDS, regions_share=0.0), n=64)  # no paper's regions: 9
    full = env.state.swim_scale == 1
    assert 0 < full.sum() < 64 and torch.equal(flags, torch.where(full, 5.0, 0.0))
    assert scene_flags(SumFamily([UniformFamily(), UniformFamily()]), FamilyTask(WAKE_BOUNDS), n=64)[1].eq(6).all()


def test_a_full_speed_swimmer_in_a_random_flow_or_one_on_a_current_is_the_free_scene():
    turned = TransformedFamily([synthetic_wake()], angle_deg=(10, 80), strength=(1, 1), background=(0, 0))
    on_current = SumFamily([FourierFamily(), UniformFamily()])
    from flownav.flows.families import vortex_street_family

    street = vortex_street_family(variants=1)  # a street carries its cylinder: the obstacle scene, as a wake
    members = [FourierFamily(), on_current, turned, street, UniformFamily()]
    flow = MixtureFamily(members, [1.0] * 5, WAKE_BOUNDS)
    env, flags = scene_flags(flow, FamilyTask(WAKE_BOUNDS, regions_share=0.0, full_speed_share=0.5), n=1024)
    member, full = env.flow.params["member"], env.state.swim_scale == 1
    free = (member < 2) & full
    assert 100 < free.sum() < 1024 and torch.equal(flags == 8, free)
    assert torch.equal(flags == 0, (member < 4) & ~full)  # a weaker swimmer there: none
    assert torch.equal(flags == 5, ((member == 2) | (member == 3)) & full) and torch.equal(flags == 6, member == 4)
    assert scene_flags(synthetic_wake(), swim_speed_scale=1.0)[1].ne(8).all()  # not a family: never free


def test_free_flows_go_to_the_flow_compensating_expert_when_asked():
    generalist, expert = Constant([0.1, 0.2, 0.3], 23), Constant([0.9, -0.5, 0.0], 9)
    obs = torch.randn(5, 25)
    obs[:, -1] = torch.tensor([8.0, 0.0, 8.0, 6.0, 5.0])
    plain = SceneRoutedTeacher(generalist, expert)(obs)
    assert torch.equal(plain, torch.tensor([[0.1, 0.2, 0.3]]).expand(5, 3))
    routed = SceneRoutedTeacher(generalist, expert, free_flows="compensating")(obs)
    assert torch.equal(routed[[0, 2]], FlowCompensating()(obs[[0, 2], :-2]))
    assert torch.equal(routed[[1, 3, 4]], plain[[1, 3, 4]])
    assert not torch.equal(routed[[0, 2]], plain[[0, 2]])
    capped = SceneRoutedTeacher(generalist, expert, free_flows="capped")(obs)
    assert torch.equal(capped[[0, 2]], FlowCompensating(min_progress=CAPPED_MIN_PROGRESS)(obs[[0, 2], :-2]))
    assert torch.equal(capped[[1, 3, 4]], plain[[1, 3, 4]])
    with pytest.raises(ValueError, match=r"^free_flows is 'all'; choose one of \(None, 'compensating', 'capped'\)"):
        SceneRoutedTeacher(generalist, expert, free_flows="all")


def test_every_other_wake_episode_goes_to_the_wake_expert_or_else_the_generalist():
    generalist, expert = Constant([0.1, 0.2, 0.3], 23), Constant([0.9, -0.5, 0.0], 9)
    obs = torch.randn(6, 25)
    obs[:, -1] = torch.tensor([5.0, 0.0, 1.0, 5.0, 4.0, 3.0])
    plain = SceneRoutedTeacher(generalist, expert)(obs)
    assert torch.equal(plain[[0, 1, 3, 5]], torch.tensor([[0.1, 0.2, 0.3]]).expand(4, 3))
    wake = SceneRoutedTeacher(generalist, expert, wake=Constant([0.6, -0.2, 0.4], 23))(obs)  # reads geo_priv
    assert torch.equal(wake[[0, 3]], torch.tensor([[0.6, -0.2, 0.4]]).expand(2, 3))
    assert torch.equal(wake[[1, 2, 4, 5]], plain[[1, 2, 4, 5]])


def test_the_papers_regions_in_other_wakes_go_to_their_expert_or_else_where_the_other_wake_episodes_go():
    generalist, expert = Constant([0.1, 0.2, 0.3], 23), Constant([0.9, -0.5, 0.0], 9)
    wake, regions = Constant([0.6, -0.2, 0.4], 23), Constant([-0.3, 0.6, -0.7], 23)
    obs = torch.randn(5, 25)
    obs[:, -1] = torch.tensor([9.0, 5.0, 1.0, 9.0, 0.0])
    plain = SceneRoutedTeacher(generalist, expert)(obs)
    assert torch.equal(plain[[0, 1, 3, 4]], torch.tensor([[0.1, 0.2, 0.3]]).expand(4, 3))
    with_wake = SceneRoutedTeacher(generalist, expert, wake=wake)(obs)
    assert torch.equal(with_wake[[0, 1, 3]], torch.tensor([[0.6, -0.2, 0.4]]).expand(3, 3))
    both = SceneRoutedTeacher(generalist, expert, wake=wake, wake_regions=regions)(obs)
    assert torch.equal(both[[0, 3]], torch.tensor([[-0.3, 0.6, -0.7]]).expand(2, 3))
    assert torch.equal(both[[1, 2, 4]], with_wake[[1, 2, 4]])
    net = DeterministicPolicy(23, LOW, HIGH, hidden=[8])
    routed = scene_routed(
        DeterministicPolicy(23, LOW, HIGH, hidden=[8]),
        "geo_priv",
        {
            "scene_expert": ("t.pt", DeterministicPolicy(9, LOW, HIGH, hidden=[8]), "geo_sincos"),
            "scene_wake_regions_expert": ("r.pt", net, "geo_priv"),
        },
    )
    assert routed.wake_regions is net and routed.wake is None


def test_currents_go_to_the_flow_compensating_expert_when_asked():
    generalist, expert = Constant([0.1, 0.2, 0.3], 23), Constant([0.9, -0.5, 0.0], 9)
    obs = torch.randn(4, 25)
    obs[:, -1] = torch.tensor([6.0, 0.0, 6.0, 5.0])
    plain = SceneRoutedTeacher(generalist, expert)(obs)
    assert torch.equal(plain, torch.tensor([[0.1, 0.2, 0.3]]).expand(4, 3))
    routed = SceneRoutedTeacher(generalist, expert, currents="all")(obs)
    assert torch.equal(routed[[0, 2]], FlowCompensating()(obs[[0, 2], :-2]))
    assert torch.equal(routed[[1, 3]], plain[[1, 3]])


def test_vertical_routing_sends_only_the_mostly_vertical_currents_to_the_flow_compensating_expert():
    generalist, expert = Constant([0.1, 0.2, 0.3], 23), Constant([0.9, -0.5, 0.0], 9)
    obs = torch.randn(6, 25)
    obs[:, -1] = torch.tensor([6.0, 6.0, 6.0, 6.0, 5.0, 6.0])
    obs[:, GEO_PRIV_FLOW] = torch.tensor(
        [[0.0, 0.0, 0.8], [0.0, 0.0, -0.5], [0.6, 0.0, 0.5], [0.3, -0.4, 0.4], [0.0, 0.0, 0.8], [0.0, 0.0, 0.0]]
    )  # up, down, tilted 40 deg from horizontal, 39 deg, a wake scene, still water
    routed = SceneRoutedTeacher(generalist, expert, currents="vertical")(obs)
    assert torch.equal(routed[:2], FlowCompensating()(obs[:2, :-2]))
    assert torch.equal(routed[2:], torch.tensor([[0.1, 0.2, 0.3]]).expand(4, 3))
    assert not torch.equal(routed[:2], routed[2:4])  # the two experts differ on these rows
    with pytest.raises(ValueError, match=r"^currents is True; choose one of \(None, 'all', 'vertical'\)"):
        SceneRoutedTeacher(generalist, expert, currents=True)


def test_scene_routing_needs_the_generalist_view_and_one_action_box():
    generalist = DeterministicPolicy(23, LOW, HIGH, hidden=[8])
    expert = DeterministicPolicy(9, LOW, HIGH, hidden=[8])
    routed = scene_routed(generalist, "geo_priv", {"scene_expert": ("teacher.pt", expert, "geo_sincos")})
    assert isinstance(routed, SceneRoutedTeacher) and routed.reverse is None
    with pytest.raises(CheckpointError, match="reads 'geo_sincos': pass the generalist teacher"):
        scene_routed(expert, "geo_sincos", {"scene_expert": ("teacher.pt", expert, "geo_sincos")})
    away = DeterministicPolicy(23, LOW, HIGH, hidden=[8])
    routed = scene_routed(
        generalist,
        "geo_priv",
        {"scene_expert": ("t.pt", expert, "geo_sincos"), "scene_away_expert": ("a.pt", away, "geo_priv")},
    )
    assert routed.away is away and routed.reverse is None and routed.wake is None
    wake = DeterministicPolicy(23, LOW, HIGH, hidden=[8])
    routed = scene_routed(
        generalist,
        "geo_priv",
        {"scene_expert": ("t.pt", expert, "geo_sincos"), "scene_wake_expert": ("w.pt", wake, "geo_priv")},
    )
    assert routed.wake is wake and routed.away is None and routed.posed is None
    routed = scene_routed(
        generalist,
        "geo_priv",
        {"scene_expert": ("t.pt", expert, "geo_sincos"), "scene_posed_expert": ("p.pt", wake, "geo_priv")},
    )
    assert routed.posed is wake and routed.wake is None
    other = DeterministicPolicy(9, LOW, [2.0, 0.785, 1.571], hidden=[8])
    with pytest.raises(CheckpointError, match="algo.scene_reverse_expert other.pt acts in another action box"):
        scene_routed(
            generalist,
            "geo_priv",
            {
                "scene_expert": ("teacher.pt", expert, "geo_sincos"),
                "scene_reverse_expert": ("other.pt", other, "geo_sincos"),
            },
        )


def posed_and_turned_wakes() -> MixtureFamily:
    """Member 0: the wake as posed; member 1: the wake turned by 10-80 degrees."""
    posed = TransformedFamily([synthetic_wake()], angle_deg=(0, 0), strength=(1, 1), background=(0, 0))
    turned = TransformedFamily([synthetic_wake()], angle_deg=(10, 80), strength=(1, 1), background=(0, 0))
    return MixtureFamily([posed, turned], [1.0, 1.0], WAKE_BOUNDS)


def test_the_scene_is_set_at_each_reset_and_rebuilt_when_a_saved_state_is_loaded():
    """The code is an episode's (computed at its reset, the same as paper_scene of the state), is not saved
    with the env's state, and an env that loads that state sees the same codes and steps on identically."""
    from flownav.envs.core import paper_scene

    task = FamilyTask(WAKE_BOUNDS, regions_share=0.0, posed_wake_regions_share=1.0, posed_wake_reverse_share=0.5)
    make = lambda seed: NavigationEnv(posed_and_turned_wakes(), task, num_envs=64, views=("geo_priv_scene",), seed=seed)  # noqa: E731
    env = make(5)
    td = env.reset()
    for _ in range(40):
        td["action"] = env.action_spec.rand()
        td = env.step_and_maybe_reset(td)[1]
    assert (env.state.steps < 40).any()  # some episodes ended and restarted in place
    assert torch.equal(env.state.scene, paper_scene(env.state, env.flow, env.settings))
    assert {0, 1, 3, 5} >= set(env.state.scene.tolist()) and len(set(env.state.scene.tolist())) >= 3
    saved = env.state_dict()
    assert "scene" not in saved
    other = make(9)
    other.reset()
    other.load_state_dict(saved)
    assert torch.equal(other.state.scene, env.state.scene)
    action = env.action_spec.rand()
    a = env.step(td.clone().set("action", action))["next"]
    b = other.step(td.clone().set("action", action))["next"]
    assert torch.equal(a["geo_priv_scene"], b["geo_priv_scene"])


def test_the_family_task_poses_the_papers_task_in_the_posed_wake():
    flow = posed_and_turned_wakes()
    task = FamilyTask(WAKE_BOUNDS, regions_share=0.0, posed_wake_regions_share=1.0)
    env = NavigationEnv(flow, task, num_envs=512, views=("geo_sincos",), seed=2)
    env.reset()
    papers = REGION_1.contains(env.state.pos) & REGION_2.contains(env.state.target)
    assert 100 < papers.sum() < 412 and torch.equal(papers, env.flow.params["member"] == 0)


def test_the_any_start_share_acts_without_the_posed_wake_regions_share():
    """posed_wake_any_start_share moves the posed wake's starts whether or not posed_wake_regions_share is set."""
    flow = posed_and_turned_wakes()
    task = FamilyTask(WAKE_BOUNDS, regions_share=1.0, posed_wake_any_start_share=1.0)
    env = NavigationEnv(flow, task, num_envs=512, views=("geo_sincos",), seed=2)
    env.reset()
    from_region_1 = REGION_1.contains(env.state.pos)
    in_posed = env.flow.params["member"] == 0
    assert REGION_2.contains(env.state.target).all() and from_region_1[~in_posed].all()
    assert from_region_1[in_posed].float().mean() < 0.1  # Region 1 is a small share of the domain


def _rot(a: torch.Tensor) -> torch.Tensor:
    """[N, 3, 3] rotations about z by ``a``."""
    c, s, z, o = torch.cos(a), torch.sin(a), torch.zeros_like(a), torch.ones_like(a)
    return torch.stack((torch.stack((c, -s, z), -1), torch.stack((s, c, z), -1), torch.stack((z, z, o), -1)), 1)


def test_turning_geo_priv_back_undoes_a_turn_of_the_whole_scene():
    """A scene turned by a about z: its vectors R v, heading theta + a, flow R u, gradient R G R^T. Turned back, its
    geo_priv is the unturned scene's, number for number (the scalars untouched)."""
    g = torch.Generator().manual_seed(0)
    n = 64
    a = (torch.rand(n, generator=g) * 2 - 1) * math.pi
    d, v, u = (torch.randn(n, 3, generator=g) for _ in range(3))
    grad = torch.randn(n, 3, 3, generator=g)
    theta, psi, rest = (torch.rand(n, generator=g) * 2 - 1) * math.pi, torch.rand(n, generator=g), torch.randn(n, 2)

    def geo_priv(d, v, theta, u, grad):
        heading = torch.stack((torch.cos(theta), torch.sin(theta), psi), -1)
        return torch.cat((d, v, heading, u, grad.flatten(1), rest), -1)

    r = _rot(a)
    turn = lambda x: (r @ x[..., None])[..., 0]  # noqa: E731
    turned = geo_priv(turn(d), turn(v), theta + a, turn(u), r @ grad @ r.transpose(1, 2))
    assert torch.allclose(turn_geo_priv(turned, a), geo_priv(d, v, theta, u, grad), atol=1e-5)
    assert torch.equal(turn_geo_priv(turned, torch.zeros(n)), turned)


def test_geo_priv_wake_turns_back_each_slots_drawn_rotation_and_the_router_feeds_it_to_its_experts():
    turned = TransformedFamily([synthetic_wake()], angle_deg=(-90, 90), strength=(1, 1), background=(0, 0))
    flow = MixtureFamily([turned, UniformFamily()], [1.0, 1.0], WAKE_BOUNDS)
    env = NavigationEnv(flow, FamilyTask(WAKE_BOUNDS), num_envs=128, views=("geo_priv", "geo_priv_wake"), seed=2)
    td = env.reset()
    angle = torch.atan2(env.flow.members[0].params["sin"], env.flow.members[0].params["cos"])
    in_wake = env.flow.params["member"] == 0
    assert 30 < in_wake.sum() < 100 and angle[in_wake].abs().max() > 1.0
    expected = turn_geo_priv(td["geo_priv"], torch.where(in_wake, angle, 0.0))
    assert torch.allclose(td["geo_priv_wake"], expected, atol=1e-6)
    assert torch.equal(td["geo_priv_wake"][~in_wake], td["geo_priv"][~in_wake])  # a current is not turned
    # one flow turned (flow.rotate_deg) in a misaligned scene: the two turns add up
    views = ("geo_priv", "geo_priv_wake")
    env = NavigationEnv(RotatedFlow(synthetic_wake(), 40.0, (9.0, 0.0)), views=views, num_envs=32, misalignment_deg=30)
    td = env.reset()
    assert torch.allclose(td["geo_priv_wake"], turn_geo_priv(td["geo_priv"], torch.full((32,), math.radians(70))))
    # the routed teacher: an expert trained on geo_priv_wake reads the scene's geo_priv turned back
    seen = []
    wake = Recorder([0.6, -0.2, 0.4], seen)
    obs = torch.randn(4, 25)
    obs[:, -1] = torch.tensor([5.0, 5.0, 0.0, 9.0])
    routed = scene_routed(
        DeterministicPolicy(23, LOW, HIGH, hidden=[8]),
        "geo_priv",
        {
            "scene_expert": ("t.pt", DeterministicPolicy(9, LOW, HIGH, hidden=[8]), "geo_sincos"),
            "scene_wake_expert": ("w.pt", wake, "geo_priv_wake"),
        },
    )
    assert routed.views["wake"] == "geo_priv_wake"
    out = routed(obs)
    assert torch.equal(out[[0, 1, 3]], torch.tensor([[0.6, -0.2, 0.4]]).expand(3, 3))
    assert torch.equal(seen[0], turn_geo_priv(obs[:, :-2], obs[:, -2])[[0, 1, 3]])  # its rows only
    # so does a reverse expert trained on it (scene code 3); the paper's SI-2 teacher reads geo_sincos
    for reverse_view, reads in (("geo_priv_wake", turn_geo_priv(obs[:, :-2], obs[:, -2])), ("geo_sincos", obs[:, :9])):
        seen.clear()
        obs[:, -1] = SCENE_REVERSE
        reverse = Recorder([0.1, 0.2, -0.3], seen)
        experts = {
            "scene_expert": ("t.pt", DeterministicPolicy(9, LOW, HIGH, hidden=[8]), "geo_sincos"),
            "scene_reverse_expert": ("r.pt", reverse, reverse_view),
        }
        out = scene_routed(DeterministicPolicy(23, LOW, HIGH, hidden=[8]), "geo_priv", experts)(obs)
        assert torch.equal(out, torch.tensor([[0.1, 0.2, -0.3]]).expand(4, 3))
        assert torch.equal(seen[0], reads)
    with pytest.raises(CheckpointError, match=r"^algo.scene_wake_expert w.pt reads 'geo_sincos'; that expert reads "):
        scene_routed(
            DeterministicPolicy(23, LOW, HIGH, hidden=[8]),
            "geo_priv",
            {
                "scene_expert": ("t.pt", DeterministicPolicy(9, LOW, HIGH, hidden=[8]), "geo_sincos"),
                "scene_wake_expert": ("w.pt", DeterministicPolicy(9, LOW, HIGH, hidden=[8]), "geo_sincos"),
            },
        )


def test_the_paper_scene_may_go_to_a_network_in_the_wake_frame():
    """algo.scene_expert may read geo_priv_wake: it labels the paper's scene (code 1) and, without an away expert, the
    away starts (code 4) from the view turned back by each row's turn."""
    torch.manual_seed(0)
    net = lambda n: DeterministicPolicy(n, LOW, HIGH, hidden=[16])  # noqa: E731
    experts = {"scene_expert": ("r2.pt", net(23), "geo_priv_wake")}
    routed = scene_routed(net(23), "geo_priv", experts)
    obs = torch.randn(40, 25)
    obs[:, -1] = torch.tensor([1, 4, 0, 5]).repeat(10)
    back = turn_geo_priv(obs[:, :-2], obs[:, -2])
    with torch.no_grad():
        out, labels = routed(obs), experts["scene_expert"][1](back)
        for code in (1, 4):
            rows = obs[:, -1] == code
            assert torch.allclose(out[rows], labels[rows], atol=1e-6)
        rest = obs[:, -1] >= 5
        assert not torch.allclose(out[rest], labels[rest], atol=1e-3)


class Recorder(torch.nn.Module):
    """A constant policy that keeps what it was given."""

    def __init__(self, action, seen: list):
        super().__init__()
        self.action, self.seen = torch.tensor(action), seen
        self.config = {"action_low": LOW, "action_high": HIGH}

    def forward(self, obs):
        self.seen.append(obs.clone())
        return self.action.expand(obs.shape[0], 3)


def test_each_expert_labels_only_its_own_rows_as_it_would_the_whole_batch():
    """The router runs every labeller on its own rows: the labels are those of each expert run on the whole batch."""
    torch.manual_seed(0)
    net = lambda n: DeterministicPolicy(n, LOW, HIGH, hidden=[16])  # noqa: E731
    experts = {
        "scene_expert": ("t.pt", net(9), "geo_sincos"),
        "scene_reverse_expert": ("r.pt", net(23), "geo_priv_wake"),
        "scene_away_expert": ("a.pt", net(23), "geo_priv"),
        "scene_wake_expert": ("w.pt", net(23), "geo_priv_wake"),
        "scene_wake_regions_expert": ("g.pt", net(23), "geo_priv"),
    }
    routed = scene_routed(net(23), "geo_priv", experts, currents="vertical", free_flows="capped")
    obs = torch.randn(300, 25)
    obs[:, -1] = torch.arange(300) % 10
    view, back = obs[:, :-2], turn_geo_priv(obs[:, :-2], obs[:, -2])
    whole = {
        1: experts["scene_expert"][1](obs[:, :9]),
        3: experts["scene_reverse_expert"][1](back),
        4: experts["scene_away_expert"][1](view),
        5: experts["scene_wake_expert"][1](back),
        7: experts["scene_wake_expert"][1](back),  # no posed expert: as code 5
        8: routed.free(view),
        9: experts["scene_wake_regions_expert"][1](view),
        0: routed.generalist(view),
    }
    with torch.no_grad():
        out = routed(obs)
        for code, labels in whole.items():
            rows = obs[:, -1] == code
            assert torch.allclose(out[rows], labels[rows], atol=1e-6), code
        assert torch.allclose(out[obs[:, -1] == 2], routed.upstream(view)[obs[:, -1] == 2], atol=1e-6)
        u = view[:, GEO_PRIV_FLOW]
        vertical = (u[:, 2].abs() > u[:, :2].norm(dim=-1))[:, None]  # code 6: the mostly vertical currents
        expected = torch.where(vertical, routed.upstream(view), routed.generalist(view))
        six = obs[:, -1] == 6
        assert 0 < (six & vertical[:, 0]).sum() < six.sum()
        assert torch.allclose(out[six], expected[six], atol=1e-6)
