"""Families of flows: every swimmer of a batch gets its own flow, drawn anew at each of its resets.

A :class:`FlowFamily` is a :class:`~flownav.flows.FlowField` whose parameters live per env slot. The
environment takes its own copy with :meth:`FlowFamily.bind` (``num_envs`` slots), calls :meth:`FlowFamily.resample`
for the slots it resets, and ``velocity(pos, t, idx)`` / ``in_obstacle(pos, idx)`` where row ``i`` of
``pos`` belongs to slot ``idx[i]`` (slot ``i`` when ``idx`` is None). All members share one domain box
(``bounds``); time is the episode's own (a family has no global period: members draw their phases).

Members (parameter ranges are the constructor's arguments; ``conf/flow/family_*.yaml`` sets them):

* :class:`FourierFamily`, random divergence-free unsteady flows, a sum of K helical (Beltrami) modes

      u(x, t) = sum_k A_k [a_k cos(k.x + w_k t + phi_k) + b_k sin(k.x + w_k t + phi_k)],

  with the wave vector k in a uniformly random direction, |k| = 2 pi / lambda, lambda log-uniform in
  ``wavelength``; a_k a random unit vector orthogonal to k and b_k = k/|k| x a_k, so k.a_k = k.b_k = 0 and
  div u = 0 exactly (each mode alone is a Beltrami field, curl u_k = -|k| u_k). Amplitudes follow the
  spectrum A_k ~ |k|^-p (``spectrum`` = p), phases phi_k are uniform in [0, 2 pi), frequencies w_k
  uniform in +-``frequency``. The amplitudes are scaled so that the space-time RMS speed
  sqrt(sum A_k^2) equals a speed V drawn uniformly in ``speed`` (the pointwise maximum is at most sqrt(K) V).
  With ``periodic_axes`` (the flow config's, e.g. [y, z]) each k's component on those axes is rounded to the
  nearest multiple of 2 pi / L (L: the box's size there), so the flow is periodic over the box on them; a and b
  are drawn orthogonal to the rounded k and the amplitude keeps the drawn |k|'s spectrum.
* :class:`UniformFamily`, uniform currents u = s e, e uniform on the sphere (``horizontal``: in the x-y
  plane; a share ``vertical_share`` of the draws along +z or -z instead), s uniform in ``speed``; a share
  ``still_share`` of the draws is still water (s = 0 exactly).
* :class:`TransformedFamily`, a base flow (one of ``bases`` per swimmer) under a random rotation alpha
  about the z axis through ``center``, a random strength s and time offset tau, plus a background current
  c (horizontal, random direction, magnitude uniform in ``background``):

      u(x, t) = s R(alpha) u_base(R(-alpha)(x - center) + center, t + tau) + c,

  and the base flow's obstacles move with it. Used for the CFD wake (:func:`wake_family`; outside its
  grid GridFlow clamps to the boundary values, i.e. about the free stream, and wraps the periodic span)
  and for the analytic vortex street (:func:`vortex_street_family`: a bank of streets whose shape
  parameters are drawn once from ranges, one of them per swimmer).
* :class:`MixtureFamily`, each swimmer's flow is one member, picked with probabilities ``weights``.
* :class:`SumFamily`, the superposition of its members (each drawn independently). Sums and mixtures
  of divergence-free members are divergence-free.
"""

from __future__ import annotations

import copy
import math
from collections.abc import Sequence

import torch
from torch import Tensor

from flownav.flows.base import WAKE_BOUNDS, Box, FlowField
from flownav.rows import route_rows


def _uniform(n: int, low: float, high: float, gen: torch.Generator, device, *shape) -> Tensor:
    return low + (high - low) * torch.rand(n, *shape, generator=gen, device=device)


def _unit_vectors(n: int, gen: torch.Generator, device, *shape) -> Tensor:
    v = torch.randn(n, *shape, 3, generator=gen, device=device)
    return v / v.norm(dim=-1, keepdim=True).clamp_min(1e-12)


def _check_range(value, name: str, low: float = 0.0) -> tuple[float, float]:
    lo, hi = (float(v) for v in value)
    if not low <= lo <= hi:
        raise ValueError(f"{name} must be [low, high] with {low} <= low <= high, got {list(value)}")
    return lo, hi


class FlowFamily(FlowField):
    """Per-slot flows. Subclasses implement :meth:`draw` (parameters of n new flows) and :meth:`evaluate`."""

    period = None
    obstacles = ()

    def __init__(self, bounds: Box = WAKE_BOUNDS):
        self.bounds = bounds
        self.num_slots = 0
        self.params: dict[str, Tensor] = {}
        self.members: list[FlowFamily] = []  # a family of families (mixture, sum): each member has the slots too

    # ---- what the environment calls
    def bind(self, num_slots: int, device="cpu") -> FlowFamily:
        """This family with ``num_slots`` slots of its own: an env's copy (envs share a family, not its slots).
        Shallow: base flows (a CFD grid) are shared, read-only."""
        bound = copy.copy(self)
        bound.allocate(num_slots, device)
        return bound

    def allocate(self, num_slots: int, device="cpu") -> None:
        """Room for ``num_slots`` flows, filled with a fixed draw (the env resamples every slot at reset)."""
        self.num_slots = int(num_slots)
        self.members = [m.bind(num_slots, device) for m in self.members]
        self.params = self.draw(self.num_slots, torch.Generator(device=device).manual_seed(0), device)

    def take(self, idx: Tensor) -> FlowFamily:
        """This family for the rows ``idx``: row i is slot ``idx[i]``. Many look-ups of the same rows (the oracle's
        candidate plans over a horizon) then gather each slot's parameters once, not at every call."""
        taken = copy.copy(self)
        taken.num_slots = int(idx.shape[0])
        taken.params = {key: value[idx] for key, value in self.params.items()}
        taken.members = [m.take(idx) for m in self.members]
        return taken

    def resample(self, idx: Tensor, generator: torch.Generator) -> None:
        """New flows for the slots ``idx``: this family's parameters, then each member's."""
        if not self.num_slots:
            raise RuntimeError("allocate(num_slots) the flow family before resampling it")
        for key, value in self.draw(idx.numel(), generator, idx.device).items():
            self.params[key][idx] = value
        for m in self.members:
            m.resample(idx, generator)

    def to(self, device):
        self.members = [m.to(device) for m in self.members]
        return self

    def probe(self, samples: int, generator: torch.Generator) -> FlowFamily:
        """A copy with ``samples`` slots, each its own draw (``generator``'s device), every member of a mixture in an
        equal share of the slots however small its weight: what a check of the family evaluates."""
        bound = self.bind(samples, generator.device)
        bound.resample(torch.arange(samples, device=generator.device), generator)
        bound.spread_members()
        return bound

    def spread_members(self) -> None:
        """Give every member of every mixture inside this family an equal share of the slots (see :meth:`probe`)."""
        for m in self.members:
            m.spread_members()

    def state_dict(self) -> dict:
        """Every slot's parameters (and its members'): what an exactly resumed env needs."""
        members = [m.state_dict() for m in self.members]
        return {"params": {k: v.clone() for k, v in self.params.items()}, "members": members}

    def load_state_dict(self, state: dict) -> None:
        self.params = {k: v.to(self.params[k].device).clone() for k, v in state["params"].items()}
        for m, s in zip(self.members, state["members"], strict=True):
            m.load_state_dict(s)

    def velocity(self, pos: Tensor, t: Tensor, idx: Tensor | None = None) -> Tensor:
        return self.evaluate(pos, t.to(pos.dtype), self.slot_params(pos, idx))

    def in_obstacle(self, pos: Tensor, idx: Tensor | None = None) -> Tensor:
        return torch.zeros(pos.shape[0], dtype=torch.bool, device=pos.device)

    def wake_as_posed(self, idx: Tensor) -> Tensor:
        """Which of the slots ``idx`` hold a flow with an obstacle exactly as its dataset poses it (unturned, at
        strength 1, no background): the paper's scene for the privileged ``geo_priv_scene`` view. None here."""
        return torch.zeros(idx.shape[0], dtype=torch.bool, device=idx.device)

    def holds_obstacle(self, idx: Tensor) -> Tensor:
        """Which of the slots ``idx`` hold a flow with an obstacle (a CFD wake, however turned, scaled or carried):
        the wake scene of the privileged ``geo_priv_scene`` view. None here."""
        return torch.zeros(idx.shape[0], dtype=torch.bool, device=idx.device)

    def holds_uniform(self, idx: Tensor) -> Tensor:
        """Which of the slots ``idx`` hold a uniform current (or still water): the current scene of the privileged
        ``geo_priv_scene`` view. None here."""
        return torch.zeros(idx.shape[0], dtype=torch.bool, device=idx.device)

    def turn(self, idx: Tensor) -> Tensor:
        """The angle (radians, about z) by which the flow of each of the slots ``idx`` is turned from its base flow
        as posed: what the privileged ``geo_priv_wake`` view turns back. 0 here (and for a sum, which has no one
        frame)."""
        return torch.zeros(idx.shape[0], device=idx.device)

    # ---- what members implement
    def draw(self, n: int, generator: torch.Generator, device) -> dict[str, Tensor]:  # pragma: no cover
        raise NotImplementedError

    def evaluate(self, pos: Tensor, t: Tensor, p: dict[str, Tensor]) -> Tensor:  # pragma: no cover
        raise NotImplementedError

    def slot_params(self, pos: Tensor, idx: Tensor | None) -> dict[str, Tensor]:
        """Each row's parameters: the slots ``idx`` (or all slots, in order, when idx is None)."""
        if idx is None:
            if pos.shape[0] != self.num_slots:
                raise ValueError(
                    f"a flow family evaluates one row per env slot ({self.num_slots}), got {pos.shape[0]} rows: "
                    "pass idx (the slot of each row)"
                )
            return self.params
        return {key: value[idx] for key, value in self.params.items()}

    def slots(self, pos: Tensor, idx: Tensor | None) -> Tensor:
        return torch.arange(pos.shape[0], device=pos.device) if idx is None else idx


class FourierFamily(FlowFamily):
    def __init__(
        self,
        modes: int = 8,
        wavelength: Sequence[float] = (4.0, 24.0),
        spectrum: float = 1.0,
        speed: Sequence[float] = (0.2, 1.2),
        frequency: float = 0.5,
        bounds: Box = WAKE_BOUNDS,
        periodic_axes: Sequence[int] = (),
    ):
        super().__init__(bounds)
        if int(modes) < 1 or not frequency >= 0:
            raise ValueError(f"a Fourier family needs modes >= 1 and frequency >= 0, got {modes}, {frequency}")
        self.periodic_axes = tuple(int(a) for a in periodic_axes)
        # The lattice step of each wave-vector component: 2 pi / L on a periodic axis, 0 (continuous) elsewhere.
        self.k_step = [2 * math.pi / bounds.size[a] if a in self.periodic_axes else 0.0 for a in range(3)]
        self.modes, self.spectrum, self.frequency = int(modes), float(spectrum), float(frequency)
        self.wavelength = _check_range(wavelength, "wavelength", low=1e-6)
        self.speed = _check_range(speed, "speed")
        self.max_speed = self.speed[1] * math.sqrt(self.modes)  # bound: sum A_k <= sqrt(K) sqrt(sum A_k^2)

    def draw(self, n, generator, device):
        K = self.modes
        log_lo, log_hi = (math.log(w) for w in self.wavelength)
        lam = torch.exp(_uniform(n, log_lo, log_hi, generator, device, K))
        kmag = 2 * math.pi / lam
        khat = _unit_vectors(n, generator, device, K)
        k = khat * kmag[..., None]
        if self.periodic_axes:
            step = k.new_tensor(self.k_step)
            k = torch.where(step > 0, torch.round(k / step.clamp_min(1e-12)) * step, k)
            size = k.norm(dim=-1, keepdim=True)
            khat = torch.where(size > 0, k / size.clamp_min(1e-12), khat)  # a k rounded to 0: a uniform mode
        a = _unit_vectors(n, generator, device, K)
        a = a - (a * khat).sum(-1, keepdim=True) * khat  # project out k: k.a = 0
        a = a / a.norm(dim=-1, keepdim=True).clamp_min(1e-12)
        amp = kmag ** (-self.spectrum)
        speed = _uniform(n, *self.speed, generator, device)
        amp = amp * (speed / amp.norm(dim=-1))[:, None]  # RMS speed sqrt(sum A_k^2) = speed
        return {
            "k": k,
            "a": a * amp[..., None],
            "b": torch.linalg.cross(khat, a) * amp[..., None],
            "phase": _uniform(n, 0.0, 2 * math.pi, generator, device, K),
            "omega": _uniform(n, -self.frequency, self.frequency, generator, device, K),
            "speed": speed,
        }

    def evaluate(self, pos, t, p):
        arg = torch.einsum("nkd,nd->nk", p["k"], pos) + p["omega"] * t[:, None] + p["phase"]
        return torch.einsum("nk,nkd->nd", torch.cos(arg), p["a"]) + torch.einsum("nk,nkd->nd", torch.sin(arg), p["b"])


class UniformFamily(FlowFamily):
    def __init__(
        self,
        speed: Sequence[float] = (0.0, 1.2),
        still_share: float = 0.0,
        horizontal: bool = False,
        vertical_share: float = 0.0,
        bounds: Box = WAKE_BOUNDS,
    ):
        super().__init__(bounds)
        self.speed = _check_range(speed, "speed")
        for key, share in (("still_share", still_share), ("vertical_share", vertical_share)):
            if not 0 <= share <= 1:
                raise ValueError(f"{key} is a fraction in [0, 1], got {share}")
        self.still_share, self.vertical_share = float(still_share), float(vertical_share)
        self.horizontal = bool(horizontal)
        self.max_speed = self.speed[1]

    def draw(self, n, generator, device):
        e = _unit_vectors(n, generator, device)
        if self.horizontal:
            e = torch.nn.functional.normalize(e * e.new_tensor([1.0, 1.0, 0.0]), dim=-1)
        if self.vertical_share:  # (no draw at 0: the other draws stay those of a family without the option)
            # A swimmer's ego view knows the vertical: currents along it are a regime of their own, rare on the sphere.
            vertical = torch.rand(n, generator=generator, device=device) < self.vertical_share
            up_or_down = torch.where(e[:, 2:] < 0, -1.0, 1.0) * e.new_tensor([0.0, 0.0, 1.0])  # the side e points to
            e = torch.where(vertical[:, None], up_or_down, e)
        s = _uniform(n, *self.speed, generator, device)
        still = torch.rand(n, generator=generator, device=device) < self.still_share
        return {"velocity": e * torch.where(still, 0.0, s)[:, None]}

    def evaluate(self, pos, t, p):
        return p["velocity"].to(pos.dtype).expand_as(pos).clone()

    def holds_uniform(self, idx):
        return torch.ones(idx.shape[0], dtype=torch.bool, device=idx.device)


def _rotate(vec: Tensor, cos: Tensor, sin: Tensor) -> Tensor:
    """Rotate rows of ``vec`` about z by the angles of (cos, sin) [N]."""
    x, y, z = vec.unbind(-1)
    return torch.stack((cos * x - sin * y, sin * x + cos * y, z), -1)


class TransformedFamily(FlowFamily):
    def __init__(
        self,
        bases: Sequence[FlowField],
        angle_deg: Sequence[float] = (-90.0, 90.0),
        strength: Sequence[float] = (0.25, 1.25),
        background: Sequence[float] = (0.0, 0.3),
        center: Sequence[float] = (9.0, 0.0),
        time_offset: float = 100.0,
        bounds: Box = WAKE_BOUNDS,
    ):
        super().__init__(bounds)
        if not bases:
            raise ValueError("a transformed family needs at least one base flow")
        self.bases = list(bases)
        self.angle = tuple(math.radians(a) for a in _check_range(angle_deg, "angle_deg", low=-360.0))
        self.strength = _check_range(strength, "strength")
        self.background = _check_range(background, "background")
        self.center = tuple(float(c) for c in center)
        # A base without a period starts at a time drawn in [0, time_offset); a periodic one in [0, period).
        spans = [b.period or float(time_offset) for b in self.bases]
        self.spans = torch.tensor(spans)
        self.solid = torch.tensor([bool(getattr(b, "obstacles", ())) for b in self.bases])  # which bases have one
        self.max_speed = max(b.max_speed for b in self.bases) * self.strength[1] + self.background[1]

    def to(self, device):
        self.bases = [b.to(device) for b in self.bases]
        return self

    def draw(self, n, generator, device):
        base = torch.randint(len(self.bases), (n,), generator=generator, device=device)
        angle = _uniform(n, *self.angle, generator, device)
        bg_dir = _uniform(n, -math.pi, math.pi, generator, device)
        bg = _uniform(n, *self.background, generator, device)
        tau = torch.rand(n, generator=generator, device=device) * self.spans.to(device)[base]
        return {
            "base": base,
            "cos": torch.cos(angle),
            "sin": torch.sin(angle),
            "strength": _uniform(n, *self.strength, generator, device),
            "offset": tau,
            "background": torch.stack((bg * torch.cos(bg_dir), bg * torch.sin(bg_dir), torch.zeros_like(bg)), -1),
        }

    def _to_base(self, pos: Tensor, p: dict[str, Tensor]) -> Tensor:
        c = pos.new_tensor((*self.center, 0.0))
        return _rotate(pos - c, p["cos"], -p["sin"]) + c

    def evaluate(self, pos, t, p):
        q = self._to_base(pos, p)
        tb = t + p["offset"].to(pos.dtype)

        def base_velocity(j, rows):
            return self.bases[j].velocity(q[rows], tb[rows])

        u = route_rows(p["base"], len(self.bases), base_velocity, torch.empty_like(pos))
        u = _rotate(u, p["cos"], p["sin"]) * p["strength"][:, None]
        return u + p["background"].to(pos.dtype)

    def holds_obstacle(self, idx):
        return self.solid.to(idx.device)[self.params["base"][idx]]

    def turn(self, idx):
        return torch.atan2(self.params["sin"][idx], self.params["cos"][idx])

    def wake_as_posed(self, idx):
        p = {key: value[idx] for key, value in self.params.items()}
        unturned = (p["cos"] == 1) & (p["sin"] == 0)
        return self.holds_obstacle(idx) & unturned & (p["strength"] == 1) & (p["background"] == 0).all(-1)

    def in_obstacle(self, pos, idx=None):
        p = self.slot_params(pos, idx)
        q = self._to_base(pos, p)
        hit = torch.zeros(pos.shape[0], dtype=torch.bool, device=pos.device)
        return route_rows(p["base"], len(self.bases), lambda j, rows: self.bases[j].in_obstacle(q[rows]), hit)


class MixtureFamily(FlowFamily):
    """Each slot's flow is one member, picked with probability proportional to ``weights``."""

    def __init__(self, members: Sequence[FlowFamily], weights: Sequence[float], bounds: Box = WAKE_BOUNDS):
        super().__init__(bounds)
        if not members or len(members) != len(weights) or any(w < 0 for w in weights) or sum(weights) <= 0:
            raise ValueError(f"a mixture needs one weight >= 0 per member, not all 0; got {list(weights)}")
        self.members = list(members)
        self.weights = torch.tensor([float(w) for w in weights])
        self.max_speed = max(m.max_speed for m in self.members)

    def draw(self, n, generator, device):
        return {"member": torch.multinomial(self.weights.to(device), n, replacement=True, generator=generator)}

    def spread_members(self):
        member = self.params["member"]
        drawn = torch.nonzero(self.weights > 0).flatten().to(member.device)  # a member of weight 0 is never drawn
        self.params["member"] = drawn[torch.arange(member.shape[0], device=member.device) % drawn.numel()]
        super().spread_members()

    def velocity(self, pos, t, idx=None):
        slots = self.slots(pos, idx)
        member = self.slot_params(pos, idx)["member"]

        def member_velocity(j, rows):
            return self.members[j].velocity(pos[rows], t[rows], slots[rows])

        return route_rows(member, len(self.members), member_velocity, torch.empty_like(pos))

    def in_obstacle(self, pos, idx=None):
        slots = self.slots(pos, idx)
        member = self.slot_params(pos, idx)["member"]
        hit = torch.zeros(pos.shape[0], dtype=torch.bool, device=pos.device)
        return route_rows(member, len(self.members), lambda j, r: self.members[j].in_obstacle(pos[r], slots[r]), hit)

    def wake_as_posed(self, idx):
        return self._member_flag("wake_as_posed", idx)

    def holds_obstacle(self, idx):
        return self._member_flag("holds_obstacle", idx)

    def holds_uniform(self, idx):
        return self._member_flag("holds_uniform", idx)

    def turn(self, idx):
        return self._member_flag("turn", idx, dtype=torch.get_default_dtype())

    def _member_flag(self, name: str, idx: Tensor, dtype=torch.bool) -> Tensor:
        """A per-slot flag (``wake_as_posed``, ``holds_obstacle``, ``holds_uniform``) or value (``turn``) of each
        slot's member."""
        member = self.params["member"][idx]
        flag = torch.zeros(idx.shape[0], dtype=dtype, device=idx.device)
        return route_rows(member, len(self.members), lambda j, rows: getattr(self.members[j], name)(idx[rows]), flag)


class SumFamily(FlowFamily):
    """The superposition of its members' flows, each drawn independently per slot."""

    def __init__(self, members: Sequence[FlowFamily], bounds: Box = WAKE_BOUNDS):
        super().__init__(bounds)
        if not members:
            raise ValueError("a sum family needs at least one member")
        self.members = list(members)
        self.max_speed = sum(m.max_speed for m in self.members)

    def draw(self, n, generator, device):
        return {}  # nothing of its own: each member draws its flow

    def velocity(self, pos, t, idx=None):
        return sum(m.velocity(pos, t, idx) for m in self.members)

    def in_obstacle(self, pos, idx=None):
        hit = torch.zeros(pos.shape[0], dtype=torch.bool, device=pos.device)
        for m in self.members:
            hit |= m.in_obstacle(pos, idx)
        return hit

    def holds_obstacle(self, idx):
        solid = torch.zeros(idx.shape[0], dtype=torch.bool, device=idx.device)
        for m in self.members:
            solid |= m.holds_obstacle(idx)
        return solid

    def holds_uniform(self, idx):
        uniform = torch.ones(idx.shape[0], dtype=torch.bool, device=idx.device)
        for m in self.members:
            uniform &= m.holds_uniform(idx)
        return uniform


def wake_family(wake: FlowField, **kwargs) -> TransformedFamily:
    """The CFD wake under random rotation about z, strength and phase, on a random background current."""
    return TransformedFamily([wake], **kwargs)


# Shape parameters of the vortex street family's bank: (low, high) of each VortexStreetFlow argument.
VORTEX_STREET_RANGES = {
    "period": (4.0, 7.0),
    "advection": (0.7, 0.95),
    "circulation": (1.0, 2.6),
    "core_radius": (0.3, 0.6),
    "half_spacing": (0.35, 0.6),
    "spreading": (0.0, 0.05),
    "deficit": (0.1, 0.45),
}


def vortex_street_family(variants: int = 8, seed: int = 0, bounds: Box = WAKE_BOUNDS, **kwargs) -> TransformedFamily:
    """A bank of ``variants`` analytic vortex streets, each argument uniform in VORTEX_STREET_RANGES (drawn
    once, with ``seed``); per swimmer one of them under random rotation, strength, phase and background."""
    from flownav.flows.vortex_street import VortexStreetFlow

    if int(variants) < 1:
        raise ValueError(f"vortex_street_family needs variants >= 1, got {variants}")
    gen = torch.Generator().manual_seed(int(seed))
    bank = []
    for _ in range(int(variants)):
        draw = torch.rand(len(VORTEX_STREET_RANGES), generator=gen).tolist()
        kw = {k: lo + (hi - lo) * u for (k, (lo, hi)), u in zip(VORTEX_STREET_RANGES.items(), draw, strict=True)}
        bank.append(VortexStreetFlow(**kw, bounds=bounds))
    return TransformedFamily(bank, bounds=bounds, **kwargs)
