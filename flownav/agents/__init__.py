"""Policy and value networks."""

from flownav.agents.networks import DeterministicPolicy, ObsNormalizer, SquashedAction, mlp

__all__ = ["DeterministicPolicy", "ObsNormalizer", "SquashedAction", "mlp"]
