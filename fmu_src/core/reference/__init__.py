"""Independent references of the regulator core that the tests and the benchmarks compare it
against: ``rates`` (the networks operation by operation, as nengo writes them) and ``nengo_model``
(the three networks as a nengo model; needs nengo, a test extra).  No FMU slave imports them, so
they never travel inside an FMU."""
