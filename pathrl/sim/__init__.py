"""Physics of the sensory-feedback tasks: the :class:`~pathrl.sim.feedback.Feedback` protocol the env calls and
the plate's constants (:mod:`pathrl.sim.feedback`, with the analytic ball), and the PyBullet scenes that implement it
in worker processes (:mod:`pathrl.sim.vec`, :mod:`pathrl.sim.ball_plate`, :mod:`pathrl.sim.humanoid`)."""
