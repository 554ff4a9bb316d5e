"""How closely student networks of several sizes fit one DAgger run's labels: the run's saved buffer (the
(observation, teacher action) pairs its last iterations aggregated, kept in ``<run>/checkpoints/last.pt``) split
at random 90/10, each network fitted from scratch on the 90 for the same number of Adam steps (the run's batch,
learning rate, gradient clip, prior and normaliser), and its eq. 9 loss on the held-out 10 printed as it goes.
A network that reaches a lower held-out loss imitates the run's experts more closely; whether that buys success
is for a training round to show (docs/generalist_variants.md quotes it).

    python scripts/student_capacity.py <run>/checkpoints/last.pt          # 256x256, 512x512, 256x256x256, 384x384
    python scripts/student_capacity.py <run>/checkpoints/last.pt --steps 2000 --hidden 64,64 64,64,64
"""

from __future__ import annotations

import argparse
import time

import torch

from flownav.agents.networks import DeterministicPolicy
from flownav.algorithms.dagger import fit_step, imitation_loss, lr_at, set_normalizer_from
from flownav.checkpoint import load_checkpoint

SIZES = ("256,256", "512,512", "256,256,256", "384,384")
HELD_OUT = 0.1


def held_out_loss(policy: DeterministicPolicy, obs: torch.Tensor, labels: torch.Tensor, chunk: int = 200_000) -> float:
    policy.eval()
    with torch.no_grad():
        total = sum(
            float(imitation_loss(policy(obs[i : i + chunk]), labels[i : i + chunk])) * len(obs[i : i + chunk])
            for i in range(0, len(obs), chunk)
        )
    return total / len(obs)


def fit(payload: dict, hidden: list[int], obs, labels, train, val, steps: int, reports: int, seed: int, lr_final=None):
    """Yield (step, mean training loss since the last report, held-out loss, seconds) ``reports`` times. With
    ``lr_final`` the rate falls linearly from the run's to it over the steps."""
    cfg, algo = payload["policy"]["config"], payload["meta"]["config"]["algo"]
    torch.manual_seed(seed)
    policy = DeterministicPolicy(
        cfg["obs_dim"],
        cfg["action_low"],
        cfg["action_high"],
        hidden=hidden,
        activation=cfg["activation"],
        prior=cfg.get("prior"),
        prior_turn=cfg.get("prior_turn"),
    )
    set_normalizer_from(policy, obs[train])
    lr = float(algo["lr"])
    optim = torch.optim.Adam(policy.parameters(), lr=lr)
    every, running, t0 = max(steps // reports, 1), 0.0, time.time()
    for step in range(1, steps + 1):
        optim.param_groups[0]["lr"] = lr_at({"lr": lr, "lr_final": lr_final, "iterations": steps}, step - 1)
        idx = train[torch.randint(len(train), (int(algo["batch_size"]),))]
        policy.train()
        running += fit_step(policy, optim, obs[idx], labels[idx], algo["grad_clip"])
        if step % every == 0:
            yield step, running / every, held_out_loss(policy, obs[val], labels[val]), time.time() - t0
            running = 0.0


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument(
        "checkpoint", help="a DAgger run's checkpoint with its training state (<run>/checkpoints/last.pt)"
    )
    parser.add_argument("--hidden", nargs="+", default=list(SIZES), help="network sizes, e.g. 256,256 256,256,256")
    parser.add_argument("--steps", type=int, default=8000, help="Adam steps per network")
    parser.add_argument("--reports", type=int, default=4, help="held-out losses printed per network")
    parser.add_argument(
        "--lr-final", type=float, default=None, help="the rate at the last step (linear from the run's)"
    )
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)
    torch.set_num_threads(args.threads)
    payload = load_checkpoint(args.checkpoint)
    buffer = (payload.get("train_state") or {}).get("buffer")
    if not buffer:
        parser.error(f"{args.checkpoint} holds no DAgger buffer: give the last.pt of a DAgger run directory")
    obs, labels = buffer["obs"], buffer["teacher_action"]
    perm = torch.randperm(len(obs), generator=torch.Generator().manual_seed(args.seed))
    n_val = int(len(obs) * HELD_OUT)
    val, train = perm[:n_val], perm[n_val:]
    print(f"{len(obs):,} pairs: {len(train):,} fitted, {n_val:,} held out; {args.steps} steps per network")
    for spec in args.hidden:
        hidden = [int(h) for h in spec.split(",")]
        for step, train_loss, val_loss, secs in fit(
            payload, hidden, obs, labels, train, val, args.steps, args.reports, args.seed, args.lr_final
        ):
            print(f"hidden {spec:>12s}  step {step:6d}  train {train_loss:.4f}  held out {val_loss:.4f}  {secs:5.0f} s")


if __name__ == "__main__":
    main()
