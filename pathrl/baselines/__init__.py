"""Model-based baselines and controllers. Import from the modules; each lists its public names in ``__all__``:
:mod:`pathrl.baselines.toppra` (``solve_plan``, ``solve_segment``, ``ToppraResult``, ``ToppraStatus``),
:mod:`pathrl.baselines.ruckig_track`, :mod:`pathrl.baselines.controllers` (``CONTROLLERS``; a controller is built by
:func:`pathrl.runs.make_controller`), :mod:`pathrl.baselines.greedy_follower`, :mod:`pathrl.baselines.ball_feedback`,
:mod:`pathrl.baselines.tray_time_law`."""
