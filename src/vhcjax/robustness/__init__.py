"""Robustness of a gait: contraction, basin of attraction, slope and floor-step
sensitivity, pushes at the hip.
"""

from ._basin import (
    BASIN_CONFIG as BASIN_CONFIG,
    BasinSlice as BasinSlice,
    BasinVolume as BasinVolume,
    axis_directions as axis_directions,
    basin_slice as basin_slice,
    basin_volume as basin_volume,
    classify_section_points as classify_section_points,
    max_converging_perturbation as max_converging_perturbation,
    wilson_interval as wilson_interval,
)
from ._bisection import (
    Threshold as Threshold,
    bisect_threshold as bisect_threshold,
)
from ._contraction import (
    Contraction as Contraction,
    contraction as contraction,
    steps_to_shrink as steps_to_shrink,
)
from ._push import (
    PushThresholds as PushThresholds,
    direction as direction,
    finish_step as finish_step,
    hip_jacobian as hip_jacobian,
    impulse_step as impulse_step,
    impulse_velocity_jump as impulse_velocity_jump,
    max_push as max_push,
    pulse_past_strike as pulse_past_strike,
    pulse_step as pulse_step,
    push_bound as push_bound,
    push_recovery as push_recovery,
    push_sensitivity_autodiff as push_sensitivity_autodiff,
    push_sensitivity_transverse as push_sensitivity_transverse,
    swing_from as swing_from,
)
from ._recovery import (
    CONVERGED as CONVERGED,
    FELL as FELL,
    LABEL_NAMES as LABEL_NAMES,
    OTHER_CYCLE as OTHER_CYCLE,
    UNDECIDED as UNDECIDED,
    Recovery as Recovery,
    label_names as label_names,
    recover as recover,
)
from ._slope_sensitivity import (
    SlopeSensitivity as SlopeSensitivity,
    gait_outputs as gait_outputs,
    slope_sensitivity as slope_sensitivity,
)
from ._terrain import (
    FloorStepCompassGait as FloorStepCompassGait,
    GaitSensitivity as GaitSensitivity,
    floor_step_model as floor_step_model,
    gait_sensitivity_norm as gait_sensitivity_norm,
    max_floor_step as max_floor_step,
    terrain_recovery as terrain_recovery,
)
