"""Gradient-based walker design and the parameter atlas of the compass gait."""

from ._atlas import Atlas as Atlas
from ._atlas import atlas as atlas
from ._atlas import atlas_json as atlas_json
from ._design import DEFAULT_BOUNDS as DEFAULT_BOUNDS
from ._design import OBJECTIVES as OBJECTIVES
from ._design import PARAMETERS as PARAMETERS
from ._design import DesignResult as DesignResult
from ._design import design as design
from ._design import parameters_of as parameters_of
from ._flip import FlipScan as FlipScan
from ._flip import flip_slope as flip_slope
from ._flip import flip_slopes as flip_slopes
