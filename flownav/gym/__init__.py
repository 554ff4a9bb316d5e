"""Gymnasium environments backed by the batched :class:`~flownav.envs.navigation.NavigationEnv`.

``import flownav`` registers them when gymnasium is installed (the ``[gym]`` extra):

* ``flownav/CylinderWake-v0``: the paper's task, the CFD wake ``data/cylinder_re300``, Region 1 -> Region 2;
* ``flownav/ABC-v0``: the ABC zero-shot test (``conf/flow/abc.yaml``, ``conf/task/abc.yaml``, swim speed x 0.1).

``gymnasium.make`` gives a :class:`~flownav.gym.env.FlowNavEnv` (one swimmer), ``gymnasium.make_vec`` with
``vectorization_mode="vector_entry_point"`` a :class:`~flownav.gym.env.FlowNavVectorEnv` (B swimmers, one
batched step). This module imports only gymnasium: the flow loads when an env is made.
"""

from __future__ import annotations

# id -> keyword arguments of the env (see flownav.gym.env.FlowNavEnv); env keys as in conf/env/default.yaml.
ENV_IDS = {
    "flownav/CylinderWake-v0": {"flow": "cylinder", "task": "regions"},
    "flownav/ABC-v0": {"flow": "abc", "task": "abc", "swim_speed_scale": 0.1},
}


def register_envs() -> None:
    """Register :data:`ENV_IDS` with gymnasium (once per process)."""
    import gymnasium

    for env_id, kwargs in ENV_IDS.items():
        if env_id not in gymnasium.registry:
            gymnasium.register(
                id=env_id,
                entry_point="flownav.gym.env:FlowNavEnv",
                vector_entry_point="flownav.gym.env:FlowNavVectorEnv",
                kwargs=dict(kwargs),
            )
