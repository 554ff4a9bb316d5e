"""``python -m flownav.cfd plot``: figures of the shipped wake.

* ``wake_vorticity.png``: z-vorticity on the mid-span slice with the navigation regions,
  plus the force and spanwise-fluctuation histories of the run that produced it.
* ``wake_q.png``: Q-criterion view, points with Q above a threshold coloured by omega_z
  (scatter: no marching-cubes dependency), span tiled over the navigation box in z.
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from flownav.flows.grid import load_grid_flow  # noqa: E402

REGIONS = {"Region 1": ((8, 12), (2, 4)), "Region 2": ((8, 12), (-4, -2))}


def velocity_gradient(u: np.ndarray, h: float) -> np.ndarray:
    """``grad[..., i, j] = d u_i / d x_j`` by central differences (periodic in z)."""
    g = np.empty(u.shape[:3] + (3, 3), dtype=np.float32)
    for i in range(3):
        g[..., i, 0] = np.gradient(u[..., i], h, axis=0)
        g[..., i, 1] = np.gradient(u[..., i], h, axis=1)
        g[..., i, 2] = (np.roll(u[..., i], -1, axis=2) - np.roll(u[..., i], 1, axis=2)) / (2 * h)
    return g


def q_criterion(grad: np.ndarray) -> np.ndarray:
    s = 0.5 * (grad + np.swapaxes(grad, -1, -2))
    w = 0.5 * (grad - np.swapaxes(grad, -1, -2))
    return 0.5 * ((w**2).sum((-1, -2)) - (s**2).sum((-1, -2)))


def plot_wake(dataset: Path, out_dir: Path, frame: int = 0) -> list[Path]:
    flow = load_grid_flow(dataset)
    meta = flow.meta
    vel = np.load(dataset / "velocity.npy", mmap_mode="r")
    u = np.asarray(vel[frame], dtype=np.float32)  # [Nx, Ny, Nz, 3]
    h = meta["spacing"][0]
    (x0, y0, _), (nx, ny, nz) = meta["origin"], u.shape[:3]
    x = x0 + h * np.arange(nx)
    y = y0 + h * np.arange(ny)
    z = h * np.arange(nz)
    grad = velocity_gradient(u, h)
    wz = grad[..., 1, 0] - grad[..., 0, 1]
    out_dir.mkdir(parents=True, exist_ok=True)
    d, p = meta["diagnostics"], meta["provenance"]
    title = f"Re = {p['Re']:g}, St = {d['St']:.3f}, mean Cd = {d['Cd_mean']:.3f}, rms w/U = {d['rms_w_near_wake']:.3f}"

    # ---- slice + histories -------------------------------------------------------------
    fig = plt.figure(figsize=(10, 9))
    ax = fig.add_axes([0.08, 0.40, 0.84, 0.55])
    k = nz // 2
    lim = 3.0
    im = ax.pcolormesh(x, y, wz[:, :, k].T, cmap="RdBu_r", vmin=-lim, vmax=lim, shading="auto")
    ax.add_patch(plt.Circle((0, 0), 0.5, color="0.3"))
    for name, ((a, b), (c, e)) in REGIONS.items():
        ax.add_patch(plt.Rectangle((a, c), b - a, e - c, fill=False, ec="k", ls="--"))
        ax.text(a + 0.1, e + 0.15, name, fontsize=8)
    ax.set_aspect("equal")
    ax.set_xlabel("x / D")
    ax.set_ylabel("y / D")
    ax.set_title(f"z-vorticity at z = {z[k]:.1f} (frame {frame}); {title}", fontsize=9)
    fig.colorbar(im, ax=ax, fraction=0.02, label=r"$\omega_z D/U$")
    hist_path = dataset / "history.npz"
    if hist_path.exists():
        hist = np.load(hist_path)
        a1 = fig.add_axes([0.08, 0.06, 0.38, 0.25])
        a1.plot(hist["t"], hist["cd"], lw=0.6, label="Cd")
        a1.plot(hist["t"], hist["cl"], lw=0.6, label="Cl")
        a1.axhline(1.27, color="k", lw=0.5, ls=":", label="Cd ref 1.27")
        a1.set_ylim(-1.5, 2.5)
        a1.set_xlabel("t U / D")
        a1.legend(fontsize=7, ncol=3)
        a2 = fig.add_axes([0.57, 0.06, 0.38, 0.25])
        a2.plot(hist["rmsw_t"], hist["rmsw"], lw=0.8)
        a2.set_xlabel("t U / D")
        a2.set_ylabel("near-wake rms w / U")
        a2.set_yscale("log")
    paths = [out_dir / "wake_vorticity.png"]
    fig.savefig(paths[0], dpi=130)
    plt.close(fig)

    # ---- Q-criterion -------------------------------------------------------------------
    q = q_criterion(grad)
    thr = 0.5  # (U/D)^2: vortex cores of the shed street and the streamwise mode-B braids
    sel = q > thr
    X, Y, Z = np.meshgrid(x, y, z, indexing="ij")
    lz = nz * h
    pts = [(X[sel], Y[sel], Z[sel] + lz * t, wz[sel]) for t in range(int(np.ceil(10 / lz)))]
    px, py, pz, pc = (np.concatenate(a) for a in zip(*pts, strict=True))
    keep = pz <= 10
    rng = np.random.default_rng(0)
    idx = rng.permutation(np.nonzero(keep)[0])[:120_000]
    fig = plt.figure(figsize=(11, 7.5))
    ax = fig.add_axes([0.0, 0.0, 0.9, 0.93], projection="3d")
    sc = ax.scatter(
        px[idx],
        py[idx],
        pz[idx],
        c=pc[idx],
        cmap="coolwarm",
        vmin=-2,
        vmax=2,
        s=2.5,
        alpha=0.8,
        linewidths=0,
    )
    ax.set_box_aspect((20, 12, 10), zoom=1.1)
    ax.set_xlim(-4, 16)
    ax.set_ylim(-6, 6)
    ax.set_zlim(0, 10)
    ax.set_xlabel("x / D")
    ax.set_ylabel("y / D")
    ax.set_zlabel("z / D")
    ax.view_init(elev=35, azim=-60)
    fig.suptitle(
        f"Q > {thr} (U/D)$^2$ coloured by $\\omega_z$ (span Lz = {lz:g} tiled in z)\n" + title,
        fontsize=10,
    )
    fig.colorbar(sc, cax=fig.add_axes([0.93, 0.25, 0.015, 0.45]), label=r"$\omega_z D/U$")
    paths.append(out_dir / "wake_q.png")
    fig.savefig(paths[1], dpi=130)
    plt.close(fig)
    return paths
