"""An RL-trained HZD policy: the paper's learning baseline (trained offline, fixed in use).

:mod:`scenarios.rl_hzd.policy` is the policy (a linear map from the regulator's inputs to
the same six joint offsets, sampled once per walking step like the regulator's PD);
:mod:`scenarios.rl_hzd.train` trains it with Augmented Random Search (Mania et al. 2018)
on the nominal Cassie: ``python -m scenarios.rl_hzd.train``.  The trained weights and
their training settings are ``policy.json`` beside this file.
"""
