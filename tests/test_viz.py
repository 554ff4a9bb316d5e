"""Figures: the interactive page's traces (read back from the HTML file) and the MP4 episode movie."""

import base64
import json
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch
from matplotlib.colors import to_hex

from flownav.envs.navigation import Status
from flownav.flows import Box, Cylinder, FunctionFlow
from flownav.paths import REPO_ROOT
from flownav.viz.colors import policy_color

BOX = Box((-4.0, -3.0, 0.0), (8.0, 3.0, 4.0))


def shear(pos, t):
    """u = -y^2 / 2 + t: omega_z = dv/dx - du/dy = y exactly (and the slice's central differences are exact)."""
    u = -0.5 * pos[:, 1] ** 2 + t
    return torch.stack((u, torch.zeros_like(u), torch.zeros_like(u)), -1)


FLOW = FunctionFlow(shear, BOX, max_speed=5.0, obstacles=[Cylinder((0.0, 0.0), 0.5)])


def trajectory(start, target, status, steps=5, t0=0.0):
    """A recorded episode in run_episodes' format: a straight line from start to target."""
    s, g = torch.tensor(start), torch.tensor(target)
    pos = s + torch.linspace(0, 1, steps + 1)[:, None] * (g - s)
    alive = torch.ones(1, steps + 1, dtype=torch.bool)
    if status != Status.SUCCESS:
        alive[0, -2:] = False  # ended early: the last rows are padding
    return {
        "position": pos[None],
        "velocity": torch.zeros(1, steps + 1, 3),
        "heading": torch.zeros(1, steps + 1, 2),
        "alive": alive,
        "time": torch.arange(steps + 1) * 0.2,
        "target": g[None],
        "status": torch.tensor([int(status)]),
        "t0": torch.tensor([t0]),
    }


RUNS = {
    "teacher": trajectory([5.0, 1.0, 2.0], [5.0, -1.0, 2.0], Status.SUCCESS),
    "student": trajectory([5.0, 1.0, 2.0], [5.0, -1.0, 2.0], Status.LEFT_DOMAIN),
}


def decode(value):
    """plotly stores numpy arrays as base64 typed arrays: {"dtype", "bdata", "shape"}."""
    if isinstance(value, dict) and "bdata" in value:
        arr = np.frombuffer(base64.b64decode(value["bdata"]), dtype=np.dtype(value["dtype"]))
        return arr.reshape([int(s) for s in str(value["shape"]).split(",")]) if "shape" in value else arr
    return np.asarray(value)


def html_traces(path) -> tuple[list, dict, str]:
    """The data and layout passed to Plotly.newPlot in the file, and the whole text."""
    text = path.read_text()
    call = text.index("Plotly.newPlot(")
    start = text.index("[", text.index(",", call))
    traces, end = json.JSONDecoder().raw_decode(text, start)
    layout, _ = json.JSONDecoder().raw_decode(text, text.index("{", end))
    return traces, layout, text


def test_html_is_self_contained_with_one_colour_per_policy_and_the_flow(tmp_path):
    pytest.importorskip("plotly")
    from flownav.viz.interactive import trajectories_html

    out = trajectories_html(RUNS, FLOW, tmp_path / "page.html", title="two policies", grid=(25, 13, 9))
    traces, layout, text = html_traces(tmp_path / "page.html")
    assert out == str(tmp_path / "page.html")
    assert not re.search(r"<script[^>]*\bsrc=", text), "the page must not load scripts from the network"
    assert "Plotly.newPlot" in text and len(text) > 1_000_000  # plotly.js itself is inside

    lines = {t["name"]: t for t in traces if t["type"] == "scatter3d" and t["mode"] == "lines"}
    assert set(lines) == {"teacher (success)", "student (left_domain)"}
    for name, t in lines.items():
        policy = name.split()[0]
        assert t["line"]["color"] == to_hex(policy_color(policy))
        alive = RUNS[policy]["alive"][0].numpy()
        np.testing.assert_allclose(decode(t["x"]), RUNS[policy]["position"][0, alive, 0].numpy(), rtol=1e-6)
    assert lines["teacher (success)"]["line"]["dash"] == "solid"
    assert lines["student (left_domain)"]["line"]["dash"] == "dash"

    markers = {t["name"]: t for t in traces if t["type"] == "scatter3d" and t["mode"] == "markers"}
    assert decode(markers["start"]["x"]).tolist() == [5.0] and decode(markers["start"]["y"]).tolist() == [1.0]
    assert decode(markers["target"]["y"]).tolist() == [-1.0]

    iso = next(t for t in traces if t["type"] == "isosurface")
    assert iso["colorbar"]["title"]["text"] == "omega_z D / U"
    assert iso["isomin"] == pytest.approx(-iso["isomax"])
    # The slice at the start's height shows omega_z = y, exactly, inside the clipping range.
    sl = next(t for t in traces if t["type"] == "surface" and t["name"].startswith("omega_z"))
    y, color = decode(sl["y"]), decode(sl["surfacecolor"])
    inside = np.abs(y) < iso["cmax"]
    np.testing.assert_allclose(color[inside], y[inside], atol=1e-5)
    assert any(t["type"] == "surface" and t["name"] == "obstacle" for t in traces)
    assert layout["scene"]["xaxis"]["title"]["text"] == "x / D"


def test_movie_is_an_mp4_with_the_episode_frames(tmp_path):
    imageio_ffmpeg = pytest.importorskip("imageio_ffmpeg")
    from flownav.viz.trajectories import make_movie

    out = make_movie(RUNS["teacher"], FLOW, tmp_path / "episode.mp4", title="teacher", frames=6, fps=5)
    assert out.endswith(".mp4")
    reader = imageio_ffmpeg.read_frames(out)
    meta = next(reader)
    w, h = meta["size"]
    frames = np.stack([np.frombuffer(f, np.uint8).reshape(h, w, 3) for f in reader])
    assert frames.shape[0] == 6 and meta["fps"] == pytest.approx(5)
    assert frames.std() > 10  # a picture, not a blank frame


def test_render_script_without_chromium_stops_with_one_line(tmp_path, monkeypatch):
    """No Chromium on the machine: one line naming what to install, no traceback, no file."""
    sys.path.insert(0, str(REPO_ROOT / "scripts"))
    import render_html

    monkeypatch.setattr(render_html.shutil, "which", lambda name: None)
    with pytest.raises(SystemExit) as stop:
        render_html.main([str(tmp_path / "page.html"), str(tmp_path / "page.png")])
    message = str(stop.value.code)
    assert message.startswith("no Chromium found (tried chromium, ") and message.endswith("apt-get install -y chromium")
    assert "\n" not in message and not (tmp_path / "page.png").exists()


@pytest.mark.slow
def test_render_script_writes_a_png_when_chromium_is_present(tmp_path):
    pytest.importorskip("plotly")
    sys.path.insert(0, str(REPO_ROOT / "scripts"))
    from render_html import find_chromium

    if find_chromium() is None:
        pytest.skip("no Chromium on this machine")
    from flownav.viz.interactive import trajectories_html

    page = trajectories_html(RUNS, FLOW, tmp_path / "page.html", grid=(25, 13, 9))
    png = tmp_path / "page.png"
    cmd = [sys.executable, str(REPO_ROOT / "scripts/render_html.py"), page, str(png), "--width", "640"]
    subprocess.run(cmd, check=True, timeout=300)
    from PIL import Image

    image = np.asarray(Image.open(png).convert("RGB"))
    assert image.shape[1] == 640 and image.std() > 10  # drawn, not a blank page


def test_command_line_writes_the_page_of_each_checkpoint(tmp_path):
    pytest.importorskip("plotly")
    from flownav.viz.interactive import main

    out = tmp_path / "uniform.html"
    args = ["--checkpoint", "checkpoints/student.pt", "--checkpoint", "checkpoints/teacher.pt", "--out", str(out)]
    main([*args, "flow=uniform", "env.time_limit=2"])
    traces, layout, _ = html_traces(out)
    names = sorted(t["name"] for t in traces if t["type"] == "scatter3d" and t["mode"] == "lines")
    assert [n.split()[0] for n in names] == ["student", "teacher"]
    assert all(n.endswith("(timeout)") for n in names)  # Region 2 is >= 3.7 D away in y: not in 2 time units
    assert not any(t["name"] == "obstacle" for t in traces)  # the uniform flow has no cylinder
    assert "student, teacher in uniform" in layout["title"]["text"]


@pytest.fixture
def saved_figures(monkeypatch):
    """The matplotlib figures the plotting functions save (they close them after saving)."""
    from matplotlib.figure import Figure

    saved, save = [], Figure.savefig

    def keep(self, *args, **kwargs):
        saved.append(self)
        return save(self, *args, **kwargs)

    monkeypatch.setattr(Figure, "savefig", keep)
    return saved


def test_trajectory_figure_labels_units_colorbar_legend_and_equal_panels(tmp_path, saved_figures):
    from flownav.viz.fields import VORTICITY_LABEL
    from flownav.viz.trajectories import plot_trajectories_3d

    runs = {name: {**traj, "t0": torch.tensor([1.5])} for name, traj in RUNS.items()}
    plot_trajectories_3d(runs, FLOW, tmp_path / "traj.png", title="two policies")
    (fig,) = saved_figures
    ax3d, ax2d, cbar = fig.axes
    assert (ax3d.get_xlabel(), ax3d.get_ylabel(), ax3d.get_zlabel()) == ("x / D", "y / D", "z / D")
    assert (ax2d.get_xlabel(), ax2d.get_ylabel()) == ("x / D", "y / D")
    assert cbar.get_ylabel() == VORTICITY_LABEL and "t = 1.5 D/U" in ax2d.get_title()
    labels = [t.get_text() for legend in fig.legends for t in legend.get_texts()]
    assert labels == ["teacher (success)", "student (left_domain)", "reached the target", "failed", "start", "target"]
    lines = {line.get_label(): line for line in ax3d.get_lines() if not line.get_label().startswith("_")}
    teacher, student = lines["teacher (success)"], lines["student (left_domain)"]
    assert teacher.get_linestyle() == "-" and student.get_linestyle() == "--"
    assert teacher.get_marker() != student.get_marker() and teacher.get_zorder() != student.get_zorder()
    assert teacher.get_linewidth() > student.get_linewidth()  # the first drawn below, wider: both stay visible
    w3, w2 = (ax.get_position(original=True).width for ax in (ax3d, ax2d))
    assert w3 == pytest.approx(w2, rel=1e-6)  # panels of equal size (the x-y one keeps its aspect inside)


def test_success_maps_come_in_a_grid_with_labelled_axes_and_colorbars(tmp_path, saved_figures):
    from flownav.viz.maps import plot_success_maps

    rng = np.random.default_rng(0)
    episodes = np.full((6, 4, 2), 10)
    maps = {f"policy{k}": {"episodes": episodes, "successes": rng.integers(0, 11, (6, 4, 2))} for k in range(5)}
    files = plot_success_maps(maps, FLOW, np.array([5.0, -1.0, 2.0]), tmp_path / "maps", title="maps")
    assert len(files) == 1 + 5 and all(Path(f).is_file() for f in files)
    fig = saved_figures[0]
    panels = [ax for ax in fig.axes if ax.get_label() != "<colorbar>"]
    colorbars = [ax for ax in fig.axes if ax.get_label() == "<colorbar>"]
    assert len(panels) == 6 and len(colorbars) == 2  # 5 maps in 2 rows of 3 (one empty), not a row of 5
    assert fig.get_size_inches()[0] < 16
    assert (fig._supxlabel.get_text(), fig._supylabel.get_text()) == ("x / D", "y / D")
    bars = {cb.get_ylabel().split(" at ")[0] for cb in colorbars}
    assert bars == {"success rate (pooled over z)", r"$\omega_z D / U$"}


def test_abc_and_misalignment_panels_draw_every_episode_and_count_the_arrivals(tmp_path, saved_figures):
    from flownav.viz.trajectories import plot_abc, plot_misaligned

    both = {k: torch.cat((RUNS["teacher"][k], RUNS["student"][k])) for k in ("position", "alive", "status", "target")}
    both["t0"] = torch.tensor([0.0, 0.0])
    plot_abc({"teacher": both}, FLOW, tmp_path / "abc.png")
    plot_misaligned({("teacher", 0.0): both, ("teacher", 90.0): both}, FLOW, tmp_path / "mis.png")
    abc, mis = saved_figures
    xy, xz = abc.axes[:2]
    assert xy.get_title().startswith("teacher: 1/2 reached") and xz.get_title() == "teacher (x-z)"
    assert [line.get_linestyle() for line in xz.get_lines()] == ["-", "None", "None", "--", "None", "None"]
    assert [ax.get_title() for ax in mis.axes] == ["teacher, 0 deg: 1/2", "teacher, 90 deg: 1/2"]
