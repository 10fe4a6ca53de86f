"""The plant's shared names agree with the regulator core's outputs."""

from plant import constants
from fmu_src.core.avr_specs import OUTPUT_JOINTS, OUTPUT_SPECS


def test_offset_names_are_the_regulators_outputs_in_order():
    assert constants.OFFSET_JOINTS == OUTPUT_JOINTS
    outputs = tuple(s.name for s in OUTPUT_SPECS)
    assert constants.OFFSET_NAMES == outputs[:len(constants.OFFSET_NAMES)]
