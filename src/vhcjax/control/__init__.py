"""Orbital stabilization of gaits by transverse-linearization feedback (layer 8).

Inputs $B(q)u$ on a model, the transverse linearization with input and jump, the hybrid
periodic Riccati equation (two ways), the feedback law, and closed-loop analysis.
"""

from ._actuated import (
    ClosedLoopSimulation as ClosedLoopSimulation,
    ZeroFeedback as ZeroFeedback,
    actuated_vector_field as actuated_vector_field,
    closed_loop_step as closed_loop_step,
    in_domain as in_domain,
    input_matrix as input_matrix,
    simulate_closed_loop as simulate_closed_loop,
    step_torque as step_torque,
)
from ._closed_loop import (
    TIGHT_CONFIG as TIGHT_CONFIG,
    ClosedLoopBasin as ClosedLoopBasin,
    Stabilization as Stabilization,
    closed_loop_basin as closed_loop_basin,
    closed_loop_jacobian as closed_loop_jacobian,
    closed_loop_max_push as closed_loop_max_push,
    closed_loop_multipliers as closed_loop_multipliers,
    closed_loop_multipliers_transverse as closed_loop_multipliers_transverse,
    closed_loop_push_step as closed_loop_push_step,
    closed_loop_step_map as closed_loop_step_map,
    stabilize as stabilize,
)
from ._feedback import (
    HybridTransverseFeedback as HybridTransverseFeedback,
    TransverseFeedback as TransverseFeedback,
    transverse_feedback as transverse_feedback,
    with_torque_limit as with_torque_limit,
)
from ._riccati import (
    RiccatiSolution as RiccatiSolution,
    default_weights as default_weights,
    riccati_backward as riccati_backward,
    riccati_hamiltonian as riccati_hamiltonian,
)
from ._transverse import (
    HybridTransverseSystem as HybridTransverseSystem,
    TransverseSystem as TransverseSystem,
    jump_matrix as jump_matrix,
    transverse_system as transverse_system,
)
