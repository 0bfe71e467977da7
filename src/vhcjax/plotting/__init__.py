"""Figures and animation (matplotlib is imported when a figure is drawn)."""

from ._control import plot_stabilization as plot_stabilization
from ._gait import (
    plot_sweep as plot_sweep,
)
from ._parameters import plot_atlas as plot_atlas, plot_design as plot_design
from ._robustness import (
    SECTION_LABELS as SECTION_LABELS,
    SECTION_SYMBOLS as SECTION_SYMBOLS,
    plot_basin as plot_basin,
    plot_contraction as plot_contraction,
    plot_push as plot_push,
    plot_slope as plot_slope,
    plot_terrain as plot_terrain,
)
from ._simulation import (
    animate as animate,
    plot_phase_portrait as plot_phase_portrait,
    plot_states as plot_states,
    plot_step_periods as plot_step_periods,
    plot_walker as plot_walker,
    walker_frames as walker_frames,
)
from ._stability import (
    plot_bifurcation as plot_bifurcation,
    plot_multipliers_complex as plot_multipliers_complex,
    plot_multipliers_vs_slope as plot_multipliers_vs_slope,
)
