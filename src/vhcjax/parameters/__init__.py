"""Gradient-based walker design and the parameter atlas of the compass gait."""

from ._atlas import Atlas as Atlas, atlas as atlas, atlas_json as atlas_json
from ._design import (
    DEFAULT_BOUNDS as DEFAULT_BOUNDS,
    OBJECTIVES as OBJECTIVES,
    PARAMETERS as PARAMETERS,
    DesignResult as DesignResult,
    default_bounds as default_bounds,
    design as design,
    parameters_of as parameters_of,
)
from ._flip import FlipScan as FlipScan, flip_slope as flip_slope, flip_slopes as flip_slopes
