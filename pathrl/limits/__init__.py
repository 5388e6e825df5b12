"""Kinematic joint limits (position, velocity, acceleration, jerk). Import from the modules; each lists its public
names in ``__all__``: :mod:`pathrl.limits.feasible` (``JointLimits``, ``valid_acceleration_range``,
``action_to_acceleration``), :mod:`pathrl.limits.braking`, :mod:`pathrl.limits.integrate`, :mod:`pathrl.limits.check`
(``limit_violations``), :mod:`pathrl.limits.kernels` (compiled kernels), :mod:`pathrl.limits.backend` (``LimitBackend``:
native code and compiled kernels, one explicit setting). Modules starting with ``_`` are internal."""
