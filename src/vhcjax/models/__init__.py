"""Concrete walkers: the compass gait (thesis Table 1), the passive kneed walker and a
3-DOF walker with a pendulum at the hip.
"""

from ._compass_gait import (
    CompassGait as CompassGait,
)
from ._kneed_walker import (
    KneedWalker as KneedWalker,
)
from ._pendulum_walker import (
    PendulumWalker as PendulumWalker,
)
