"""Benchmarks of `make bench` (``tools/bench.py``, results in ``bench/*.json``; docs/performance.md): the env's steps
per second batched and single-env, PPO iterations, the time per decision, PyBullet physics, the follower's latency
and path ends (:mod:`pathrl.bench.follower`), and each family's realtime timing through its registry ``timing``
step (:mod:`pathrl.bench.suite`). Paths are synthetic smooth paths inside the joint limits (no dataset needed) where
a bench measures the env itself (:mod:`pathrl.bench.env`)."""
