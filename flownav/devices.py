"""The torch device of a run (``cfg.device``): checked once at start, and checked again once everything is built.

device = resolve_device(cfg.device)                     # ConfigError naming the fix if it is unusable
check_on_device(device, actor=actor, critic=critic, env=env)   # every parameter, buffer and the env
"""

from __future__ import annotations

import torch

from flownav.builders import ConfigError


def resolve_device(name) -> torch.device:
    """``cfg.device`` as a ``torch.device``; a one-line ConfigError if torch cannot use it on this machine."""
    try:
        device = torch.device(str(name))
    except RuntimeError as e:
        raise ConfigError(f"device={name!r} is not a torch device ({e}); use device=cpu or device=cuda") from e
    if device.type == "cuda" and not torch.cuda.is_available():
        raise ConfigError(
            f"device={name} but CUDA is not available (torch {torch.__version__}, "
            f"{'no CUDA build' if torch.version.cuda is None else 'no GPU visible'}); use device=cpu"
        )
    if device.type == "cuda" and device.index is not None and device.index >= torch.cuda.device_count():
        raise ConfigError(f"device={name} but only {torch.cuda.device_count()} CUDA device(s) are visible")
    if device.type == "mps" and not torch.backends.mps.is_available():
        raise ConfigError(f"device={name} but MPS is not available on this machine; use device=cpu")
    return device


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
