"""The native FMUs' fmi2SetDebugLogging/fmi3SetDebugLogging take only the log categories their
model description declares, as the pythonfmu FMUs' guard does: a NULL, non-UTF-8, overlong or
undeclared category is Error naming its index (and the declared ones).  The declared list is
generated once (fmu_src/regulator_fmu/native/header.py LOG_CATEGORIES) into modelDescription.xml and the C table.
"""
from ctypes import c_char_p

import pytest
from fmpy import read_model_description
from fmpy.fmi1 import FMICallException

from fmu_src.regulator_fmu.native.header import LOG_CATEGORIES
from support.native_support import logged_slave

ERROR = 3
DECLARED = [name for name, _ in LOG_CATEGORIES]


def _set_debug_logging(s, categories, n=None):
    """The raw call (fmpy's setDebugLogging cannot pass NULL or bytes that are not UTF-8)."""
    array = None if categories is None else (c_char_p * len(categories))(*categories)
    n = len(categories) if n is None else n
    if s.fmi3:
        return s.fmu.fmi3SetDebugLogging(s.fmu.component, True, n, array)
    return s.fmu.fmi2SetDebugLogging(s.fmu.component, 1, n, array)


REFUSED = {  # categories -> what the message says
    "NULL category": ([None], "categories[0] is NULL"),
    "not UTF-8": ([b"log\xffAll"], "categories[0] is not valid UTF-8"),
    "overlong": ([b"a" * 300], "categories[0] is not valid UTF-8 of at most 256 bytes"),
    "undeclared": ([b"logAll", b"logEverything"], 'categories[1] = "logEverything" is not a log category of '
                   f"this FMU (known: {', '.join(DECLARED)})"),
    "NULL array": (None, "categories is NULL with nCategories = 2"),
}


@pytest.mark.parametrize("fmi", [2, 3])
def test_native_debug_logging_takes_only_declared_categories(native_fmus, fmi):
    md = read_model_description(str(native_fmus[fmi]))
    assert [c.name for c in md.logCategories] == DECLARED  # the one table
    messages = []
    s = logged_slave(native_fmus[fmi], messages)
    for case, (categories, reason) in REFUSED.items():
        del messages[:]
        with pytest.raises(FMICallException) as info:
            _set_debug_logging(s, categories, n=2 if categories is None else None)
        assert info.value.status == ERROR, case
        assert any(reason in m for m in messages), (case, messages)
    _set_debug_logging(s, [c.encode() for c in DECLARED])  # every declared one: OK
    _set_debug_logging(s, [])  # none (all of them): OK
    s.init()  # and the instance goes on
    s.close()
