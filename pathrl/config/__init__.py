"""Config support that every layer may use (no pathrl imports): where ``conf/`` is (:mod:`pathrl.config.paths`),
saved run configs brought up to the current layout (:mod:`pathrl.config.migrate`), config keys checked against a
schema (:mod:`pathrl.config.validate`) and RSL-RL's keys checked (:mod:`pathrl.config.agent`). The apps' schemas,
composed of the env's own settings classes, sit above the env: :mod:`pathrl.schema`."""
