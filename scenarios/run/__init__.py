"""Running scenarios: one session of ``python -m scenarios run`` (arms, jobs, resume) over the master."""
