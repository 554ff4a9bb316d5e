"""Own lattice-Boltzmann generator of the 3D cylinder wake (Re = 300), its diagnostics,
validation and the default dataset ``data/cylinder_re300``. See ``docs/cfd.md``."""

from flownav.cfd.solver import CylinderLBM, SimConfig

__all__ = ["CylinderLBM", "SimConfig"]
