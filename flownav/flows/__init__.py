"""Flow fields: one batched interface ``velocity(pos[N,3], t[N]) -> [N,3]``."""

from flownav.flows.analytic import ABCFlow, UniformFlow
from flownav.flows.base import WAKE_BOUNDS, Box, Cylinder, FlowField, FunctionFlow
from flownav.flows.families import (
    FlowFamily,
    FourierFamily,
    MixtureFamily,
    SumFamily,
    TransformedFamily,
    UniformFamily,
    vortex_street_family,
    wake_family,
)
from flownav.flows.grid import GridFlow, GridFlowError, load_grid_flow, save_grid_flow
from flownav.flows.transforms import RotatedFlow, ScaledFlow, rotate_z

__all__ = [
    "ABCFlow",
    "Box",
    "Cylinder",
    "FlowFamily",
    "FlowField",
    "FourierFamily",
    "FunctionFlow",
    "GridFlow",
    "GridFlowError",
    "MixtureFamily",
    "RotatedFlow",
    "ScaledFlow",
    "SumFamily",
    "TransformedFamily",
    "UniformFamily",
    "UniformFlow",
    "WAKE_BOUNDS",
    "load_grid_flow",
    "rotate_z",
    "save_grid_flow",
    "vortex_street_family",
    "wake_family",
]
