"""Evaluation of trained policies and controllers. Import from the modules; each lists its public names in
``__all__``: :mod:`pathrl.eval.evaluate` (``evaluate``, ``EvalOptions``; a run's config and policy are loaded by
:mod:`pathrl.runs`), :mod:`pathrl.eval.rollout` (``rollout``, ``EpisodeRecord``), :mod:`pathrl.eval.metrics`,
:mod:`pathrl.eval.curve`, :mod:`pathrl.eval.limit_fuzz`, :mod:`pathrl.eval.realtime`, :mod:`pathrl.eval.path_change`
and the TrueAdapt evaluations."""
