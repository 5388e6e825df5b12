"""Motion-profile optimisation for industrial robots (Wen et al.): an ABB IRB 6640 model, a simulated
controller executing MoveL / MoveJ programs with blend zones, target trajectories and metrics, iterative waypoint
adjustment by MPGD or a learned TD3 policy, and the bisection on the speed command. See ``docs/industrial.md``.

Modules: :mod:`~pathrl.industrial.arm` (kinematics), :mod:`~pathrl.industrial.program` (programs, blended paths),
:mod:`~pathrl.industrial.controller` (the black box; ``model="abb"``: the model calibrated to a recorded ABB
controller, :mod:`~pathrl.industrial.planner`, :mod:`~pathrl.industrial.dynamics`, :mod:`~pathrl.industrial.drives`,
:mod:`~pathrl.industrial.reference`), :mod:`~pathrl.industrial.ilc` (iterative learning control),
:mod:`~pathrl.industrial.trajectories`,
:mod:`~pathrl.industrial.metrics`, :mod:`~pathrl.industrial.mpgd`, :mod:`~pathrl.industrial.speed_search`,
:mod:`~pathrl.industrial.features` / :mod:`~pathrl.industrial.iwa_env` / :mod:`~pathrl.industrial.per` /
:mod:`~pathrl.industrial.rl` / :mod:`~pathrl.industrial.rl_train` (learned IWA), :mod:`~pathrl.industrial.tables`,
:mod:`~pathrl.industrial.experiments`, :mod:`~pathrl.industrial.config`.
"""
