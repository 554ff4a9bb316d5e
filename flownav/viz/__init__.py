"""Figures: success curves and maps, 3D trajectories, velocity traces, movies (matplotlib, Agg)."""

import matplotlib

matplotlib.use("Agg")
