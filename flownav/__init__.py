"""flownav: navigation in 3D unsteady flows with geo teachers and ego students."""

from importlib.util import find_spec

# Gymnasium ids flownav/CylinderWake-v0 and flownav/ABC-v0 when the [gym] extra is installed; the flow loads at make.
if find_spec("gymnasium") is not None:
    from flownav.gym import register_envs

    register_envs()
