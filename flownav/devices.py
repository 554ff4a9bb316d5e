"""The torch device of a run (``cfg.device``): checked once at start, and checked again once everything is built.

device = resolve_device(cfg.device)                     # ConfigError naming the fix if it is unusable
check_on_device(device, actor=actor, critic=critic, env=env)   # every parameter, buffer and the env
"""

from __future__ import annotations

import torch

from flownav.errors import ConfigError


def device_problem(name) -> str | None:
    """What is wrong with ``name`` as this machine's torch device, or None."""
    try:
        device = torch.device(name)
    except (RuntimeError, TypeError):
        return "is not a torch device (cpu, cuda, cuda:0)"
    if device.type == "cuda" and not torch.cuda.is_available():
        return "asks for CUDA but torch sees no CUDA device here; use device=cpu"
    if device.type == "cuda" and device.index is not None and device.index >= torch.cuda.device_count():
        return f"names a CUDA device that is not there ({torch.cuda.device_count()} visible)"
    if device.type not in ("cpu", "cuda"):
        return "is not supported; use device=cpu or device=cuda"
    return None


def resolve_device(name) -> torch.device:
    """``cfg.device`` as a ``torch.device``; a one-line ConfigError if torch cannot use it on this machine."""
    problem = device_problem(name)
    if problem:
        raise ConfigError(f"device={name} {problem}")
    return torch.device(name)


def _same(a: torch.device, b: torch.device) -> bool:
    # "cuda" and "cuda:0" are the same device when the current device is 0.
    if a.type != b.type:
        return False
    if a.type != "cuda" or a.index is None or b.index is None:
        return True
    return a.index == b.index


def check_on_device(device, **things) -> None:
    """Raise if a parameter or buffer of a module, or an env, lives elsewhere than ``device``.

    A stray CPU tensor in a CUDA run costs a host-device copy per step (or fails); this names it at start.
    """
    device = torch.device(device)
    for name, thing in things.items():
        if isinstance(thing, torch.nn.Module):
            tensors = list(thing.named_parameters()) + list(thing.named_buffers())
        elif isinstance(thing, torch.Tensor):
            tensors = [("", thing)]
        else:  # an env (TorchRL EnvBase) carries its device
            tensors = [("device", torch.empty(0, device=thing.device))]
        for key, t in tensors:
            if not _same(t.device, device):
                where = f"{name}.{key}" if key else name
                raise RuntimeError(f"{where} is on {t.device}, the run's device is {device} (cfg.device)")
