"""Running scenarios: the ``run`` command (:mod:`scenarios.run.command`), its options
(:mod:`scenarios.run.options`), one session of it (arms, jobs, resume:
:mod:`scenarios.run.run_session`) and the arms' runner over the master (:mod:`scenarios.run.runner`)."""
