"""The plant's shared names agree with the regulator core's outputs."""

from fmu_src import avr_core
from plant import constants


def test_offset_names_are_the_regulators_outputs_in_order():
    assert constants.OFFSET_JOINTS == avr_core.OUTPUT_JOINTS
    outputs = tuple(s.name for s in avr_core.OUTPUT_SPECS)
    assert constants.OFFSET_NAMES == outputs[:len(constants.OFFSET_NAMES)]
