"""Gradient-based walker design and the parameter atlas of the compass gait."""

from ._atlas import Atlas as Atlas, atlas as atlas
from ._design import (
    DEFAULT_BOUNDS as DEFAULT_BOUNDS,
    DesignResult as DesignResult,
    OBJECTIVES as OBJECTIVES,
    PARAMETERS as PARAMETERS,
    design as design,
)
from ._flip import FlipScan as FlipScan, flip_slope as flip_slope, flip_slopes as flip_slopes
