"""Concrete walkers: the compass gait (thesis Table 1), the passive kneed walker, a
3-DOF walker with a pendulum at the hip and the simplest walking model (Garcia et al.
1998).
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
from ._simplest_walker import (
    SimplestWalker as SimplestWalker,
)
