"""Robustness of a gait: contraction, basin of attraction, slope and floor-step
sensitivity, pushes at the hip.
"""

from ._basin import (
    axis_directions as axis_directions,
    BASIN_CONFIG as BASIN_CONFIG,
    basin_slice as basin_slice,
    basin_volume as basin_volume,
    BasinSlice as BasinSlice,
    BasinVolume as BasinVolume,
    classify_section_points as classify_section_points,
    max_converging_perturbation as max_converging_perturbation,
    SECTION_NAMES as SECTION_NAMES,
    wilson_interval as wilson_interval,
)

from ._bisection import (
    bisect_threshold as bisect_threshold,
    Threshold as Threshold,
)

from ._contraction import (
    contraction as contraction,
    Contraction as Contraction,
    steps_to_shrink as steps_to_shrink,
)

from ._push import (
    finish_step as finish_step,
    swing_from as swing_from,
    direction as direction,
    hip_jacobian as hip_jacobian,
    impulse_step as impulse_step,
    impulse_velocity_jump as impulse_velocity_jump,
    max_push as max_push,
    pulse_step as pulse_step,
    push_recovery as push_recovery,
    push_sensitivity_autodiff as push_sensitivity_autodiff,
    push_sensitivity_transverse as push_sensitivity_transverse,
    PushThresholds as PushThresholds,
)

from ._recovery import (
    CONVERGED as CONVERGED,
    FELL as FELL,
    OTHER_CYCLE as OTHER_CYCLE,
    UNDECIDED as UNDECIDED,
    LABEL_NAMES as LABEL_NAMES,
    label_names as label_names,
    recover as recover,
    recover_jit as recover_jit,
    Recovery as Recovery,
)

from ._slope_sensitivity import (
    gait_outputs as gait_outputs,
    slope_sensitivity as slope_sensitivity,
    SlopeSensitivity as SlopeSensitivity,
)

from ._terrain import (
    floor_step_model as floor_step_model,
    FloorStepCompassGait as FloorStepCompassGait,
    gait_sensitivity_norm as gait_sensitivity_norm,
    GaitSensitivity as GaitSensitivity,
    max_floor_step as max_floor_step,
    terrain_recovery as terrain_recovery,
)
