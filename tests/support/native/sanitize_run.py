"""In-process work for the sanitizer test (tests/support/native/test_native_hosts.py): state round trips,
every corrupted blob of tests/support/native/test_native_state.py, and 20 instances, on the FMU given.

    python sanitize_run.py FMU OTHER_FMU     (exit 0 when every check held)
"""
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parents[2]))  # tests/: the support package
from fmpy.fmi1 import FMICallException  # noqa: E402
from support.native_support import AnySlave, input_sequence  # noqa: E402
from test_native_state import _corruptions  # noqa: E402


def main(fmu, other_fmu):
    slaves = [AnySlave(fmu, name=f"i{i}").init(n_neurons=40 + i, seed=i, learning_rate=1e-4, learn_from_step=0)
              for i in range(20)]
    seq = input_sequence(60, seed=4)
    for k, u in enumerate(seq):
        for s in slaves:
            s.step(k, u)
    s = slaves[0]
    blob = s.serialize(s.get_state())
    other = AnySlave(other_fmu, name="other").init(n_neurons=40)
    refused = 0
    for name, bad in _corruptions(blob, other.serialize(other.get_state())):
        try:
            s.deserialize(bad)
        except FMICallException:
            refused += 1
        else:
            raise AssertionError(f"accepted a corrupted state: {name}")
    s.set_state(s.deserialize(blob))
    assert np.all(np.isfinite(s.step(len(seq), seq[0])))
    for slave in slaves + [other]:
        slave.close()
    print(f"refused {refused} corrupted states")


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])
