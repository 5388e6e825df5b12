"""Environments (batched torch, rsl-rl ``VecEnv``). Import from the modules; each lists its public names in
``__all__``:

- :mod:`pathrl.envs.registry`: ``TASKS``, ``make_env(cfg, EnvRequest(split, ...))``, ``check_task``,
  ``get_task``: which env a config's task builds (the one entry point of training, evaluation and the CLIs);
  ``task_cfg`` (a config's task group, saved runs' missing keys filled in from :mod:`pathrl.config.migrate`),
  ``make_feedback`` (the task's feedback source, :mod:`pathrl.sim`);
- :mod:`pathrl.envs.tracking`: ``PathTrackingEnv``; its settings :mod:`pathrl.envs.tracking_cfg` (``EnvSettings``, the
  ``env`` config group and its only defaults; ``TrackingEnvCfg.from_run(cfg)``);
- :mod:`pathrl.envs.terminations`: ``TerminationReason`` and the termination terms;
- :mod:`pathrl.envs.observations`: ``OBS_TERMS``, the observation terms of the tracking env and their layout;
- :mod:`pathrl.envs.rewards`: reward terms (feedback sources, the analytic ball, sensors: :mod:`pathrl.sim.feedback`);
- :mod:`pathrl.envs.trueadapt`, :mod:`pathrl.envs.trueadapt_rewards`: TrueAdapt trajectory adaptation;
- :mod:`pathrl.envs.state`: snapshot / restore of an env's changing state (resumed training).
"""
