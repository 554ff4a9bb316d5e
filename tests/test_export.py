"""python -m flownav.export: the exported ONNX / TorchScript policy acts as the torch policy; its card; bad input."""

import json

import numpy as np
import pytest
import torch

from flownav.agents.networks import DeterministicPolicy
from flownav.checkpoint import load_policy, save_policy_checkpoint
from flownav.export import export_policy, main
from flownav.paths import CHECKPOINT_DIR, RESULTS_DIR
from flownav.provenance import sha256

STUDENT = CHECKPOINT_DIR / "student.pt"


def random_observations(n: int, dim: int, seed: int = 0) -> torch.Tensor:
    g = torch.Generator().manual_seed(seed)
    return torch.randn(n, dim, generator=g) * 4  # beyond the normaliser's clip too


def check_card(card: dict, fmt: str, policy: DeterministicPolicy):
    assert card["format"] == fmt and card["observation"]["view"] == "ego"
    names = [i["name"] for i in card["observation"]["inputs"]]
    assert names == [f"{v}_{a}" for v in ("to_target", "velocity") for a in ("forward", "left", "up")]
    assert card["units"] == {"L": "cylinder diameter D", "L/T": "inflow speed U", "T": "D / U"}
    bounds = [(o["low"], o["high"]) for o in card["action"]["outputs"]]
    assert bounds == list(zip(policy.config["action_low"], policy.config["action_high"], strict=True))
    assert card["training"]["flow"]["type"] == "grid" and card["training"]["task"]["type"] == "regions"
    # The suite's numbers for this very file, as results/paper.json has them.
    paper = json.loads((RESULTS_DIR / "paper.json").read_text())["experiments"]["training"]
    assert paper["policies"]["student"]["sha256"] == card["policy"]["checkpoint_sha256"] == sha256(STUDENT)
    training = next(s for s in card["success"] if s["experiment"] == "training")
    assert training["success_rate"] == paper["results"]["student"]["success_rate"]


@pytest.mark.slow
def test_onnx_export_matches_the_torch_policy(tmp_path):
    ort = pytest.importorskip("onnxruntime")
    pytest.importorskip("onnxscript")
    policy, _ = load_policy(STUDENT)
    model_path, card_path = export_policy(STUDENT, "onnx", tmp_path / "student.onnx")
    session = ort.InferenceSession(str(model_path), providers=["CPUExecutionProvider"])
    for n in (1, 257):
        obs = random_observations(n, policy.config["obs_dim"], seed=n)
        (action,) = session.run(["action"], {"observation": obs.numpy()})
        assert action.shape == (n, 3) and action.dtype == np.float32
        np.testing.assert_allclose(action, policy(obs).numpy(), atol=1e-5, rtol=0)
    card = json.loads(card_path.read_text())
    check_card(card, "onnx", policy)
    embedded = session.get_modelmeta().custom_metadata_map["flownav_card"]
    assert json.loads(embedded) == card


def test_torchscript_export_matches_the_torch_policy(tmp_path):
    policy, _ = load_policy(STUDENT)
    model_path, card_path = export_policy(STUDENT, "torchscript", tmp_path / "student.pt")
    extra = {"card.json": ""}
    scripted = torch.jit.load(str(model_path), _extra_files=extra)
    for n in (1, 257):
        obs = random_observations(n, policy.config["obs_dim"], seed=n)
        torch.testing.assert_close(scripted(obs), policy(obs), atol=1e-5, rtol=0)
    card = json.loads(card_path.read_text())
    check_card(card, "torchscript", policy)
    assert json.loads(extra["card.json"]) == card


def test_card_says_unknown_for_an_unevaluated_checkpoint(tmp_path):
    policy = DeterministicPolicy(9, [0.0, -1.0, -1.0], [1.0, 1.0, 1.0], hidden=(8,))
    ckpt = save_policy_checkpoint(tmp_path / "fresh.pt", policy, "geo_sincos", "teacher")
    _, card_path = export_policy(ckpt, "torchscript", tmp_path / "fresh_policy.pt")
    card = json.loads(card_path.read_text())
    assert card["success"].startswith("unknown: results/paper.json has no evaluation of this file")
    assert card["training"]["flow"] == "unknown" and card["units"]["L"].startswith("unknown")
    assert [i["name"] for i in card["observation"]["inputs"]][-3:] == ["cos_theta", "sin_theta", "psi"]


@pytest.mark.parametrize(
    "argv, message",
    [
        (
            ["checkpoint=checkpoints/student.pt", "format=tflite"],
            "error: format=tflite: choose one of onnx, torchscript\n",
        ),
        (
            ["checkpoint=checkpoints/nope.pt"],
            f"error: no checkpoint at {CHECKPOINT_DIR / 'nope.pt'}: train one "
            "(python train.py +experiment=teacher) or fix the path\n",
        ),
        (["format=onnx"], "error: checkpoint= is required, e.g. checkpoint=checkpoints/student.pt\n"),
        (
            ["checkpoint=checkpoints/student.pt", "fmt=onnx"],
            "error: unknown argument 'fmt=onnx'; use key=value with keys checkpoint, format, out\n",
        ),
    ],
)
def test_bad_arguments_one_line(argv, message, capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # nothing may be written, anywhere
    with pytest.raises(SystemExit) as exit_:
        main(argv)
    assert exit_.value.code == 2
    assert capsys.readouterr().err == message
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("flag", ["--help", "-h"])
def test_help_lists_every_argument_and_writes_nothing(flag, capsys, tmp_path, monkeypatch):
    from flownav.export import ARGUMENTS, FORMATS

    monkeypatch.chdir(tmp_path)
    assert main([flag]) == 0
    out = capsys.readouterr().out
    assert out.startswith("usage: python -m flownav.export checkpoint=PATH")
    assert all(f"\n  {key} " in out for key in ARGUMENTS) and all(fmt in out for fmt in FORMATS)
    assert list(tmp_path.iterdir()) == []


def test_every_student_view_names_each_of_its_numbers_in_order():
    """An exported card names one input per number of its view, uniquely, in order: for every view a student or
    teacher reads (a view added without names, or with one too few, fails here)."""
    from flownav.algorithms.dagger import STUDENT_VIEWS
    from flownav.envs.observations import observation_size
    from flownav.export import VIEW_INPUTS, observation_inputs

    assert set(STUDENT_VIEWS) <= set(VIEW_INPUTS)
    for view in VIEW_INPUTS:
        inputs = observation_inputs(view)
        assert [i["index"] for i in inputs] == list(range(observation_size(view))), view
        assert len({i["name"] for i in inputs}) == len(inputs), view


def test_an_export_into_a_shipped_place_is_refused_where_it_would_be_written(tmp_path, monkeypatch):
    """out= is judged where the file goes, relative to the working directory: ../checkpoints/ from a folder of the
    repository is a shipped place; checkpoints/ inside another folder is not."""
    from flownav.errors import ConfigError
    from flownav.export import export_policy
    from flownav.paths import REPO_ROOT

    monkeypatch.chdir(REPO_ROOT / "docs")
    with pytest.raises(ConfigError, match=r"^out=\.\./checkpoints/new\.onnx is in a shipped place"):
        export_policy(REPO_ROOT / "checkpoints" / "student.pt", "onnx", "../checkpoints/new.onnx")
    assert not (REPO_ROOT / "checkpoints" / "new.onnx").exists()
    monkeypatch.chdir(tmp_path)
    out, card = export_policy(REPO_ROOT / "checkpoints" / "student.pt", "onnx", "checkpoints/new.onnx")
    assert out.resolve() == (tmp_path / "checkpoints" / "new.onnx").resolve() and card.is_file()
