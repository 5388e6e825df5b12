"""Environments (batched torch, rsl-rl ``VecEnv``). Import from the modules; each lists its public names in
``__all__``:

- :mod:`pathrl.envs.registry`: ``TASKS``, ``make_env(cfg, split, ...)``, ``check_task``, ``get_task``: which env a
  config's task builds (the one entry point of training, evaluation and the CLIs);
- :mod:`pathrl.envs.tracking`: ``PathTrackingEnv``; its settings :mod:`pathrl.envs.tracking_cfg` (``EnvSettings``, the
  ``env`` config group and its only defaults; ``TrackingEnvCfg.from_run(cfg)``);
- :mod:`pathrl.envs.terminations`: ``TerminationReason`` and the termination terms;
- :mod:`pathrl.envs.observations`: ``OBS_TERMS``, the observation terms of the tracking env and their layout;
- :mod:`pathrl.envs.rewards`: reward terms; :mod:`pathrl.envs.feedback`: the analytic ball and sensors;
- :mod:`pathrl.envs.trueadapt`, :mod:`pathrl.envs.trueadapt_rewards`: TrueAdapt trajectory adaptation;
- :mod:`pathrl.envs.factory`: config glue (``task_cfg``, ``make_feedback``); saved runs are brought up to date by
  :mod:`pathrl.config.migrate`;
- :mod:`pathrl.envs.state`: snapshot / restore of an env's changing state (resumed training).
"""
