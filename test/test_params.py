"""ParamSpec.coerce (riann_ros.params): a parameter takes what YAML, the command line or a launch file make of its
natural spellings, and refuses what is not that parameter with a message naming it."""

from __future__ import annotations

import pytest

from riann_ros.magcal.input import MAG_PARAMS
from riann_ros.nodes.parameters import NODE_PARAMS
from riann_ros.params import ParamSpec, find


@pytest.mark.parametrize("spec, value, want", [
    (find(MAG_PARAMS, "use_mag"), False, "false"),
    (find(MAG_PARAMS, "use_mag"), True, "true"),
    (find(MAG_PARAMS, "use_mag"), "Auto", "auto"),
    (find(NODE_PARAMS, "world_frame"), "NED", "ned"),
    (find(NODE_PARAMS, "nominal_rate"), 200, 200.0),
    (find(NODE_PARAMS, "nominal_rate"), "200", 200.0),
    (find(NODE_PARAMS, "input_depth"), 500.0, 500),
    (find(NODE_PARAMS, "publish_rpy"), "true", True),
    (find(NODE_PARAMS, "publish_rpy"), "off", False),
    (find(NODE_PARAMS, "publish_rpy"), 1, True),
    (find(NODE_PARAMS, "fixed_frame"), 7, "7"),
    (find(MAG_PARAMS, "mag_hard_iron"), [0, 0, 1], (0.0, 0.0, 1.0)),
    (find(MAG_PARAMS, "mag_hard_iron"), "0, 0, 1e-6", (0.0, 0.0, 1e-6)),
])
def test_coerce_takes_natural_spellings(spec: ParamSpec, value, want) -> None:
    got = spec.coerce(value)
    assert got == want and type(got) is type(want)


@pytest.mark.parametrize("spec, value, error", [
    (find(MAG_PARAMS, "use_mag"), "sometimes", "use_mag must be one of auto, true, false"),
    (find(NODE_PARAMS, "publish_rpy"), "maybe", "publish_rpy must be a bool"),
    (find(NODE_PARAMS, "publish_rpy"), 2, "publish_rpy must be a bool"),
    (find(NODE_PARAMS, "nominal_rate"), "fast", "nominal_rate must be a number"),
    (find(NODE_PARAMS, "nominal_rate"), 0, "below its minimum"),
    (find(NODE_PARAMS, "input_depth"), 2.5, "input_depth must be an integer"),
    (find(MAG_PARAMS, "mag_hard_iron"), [0, 0], "must be a list of 3 numbers"),
])
def test_coerce_refuses_what_is_not_the_parameter(spec: ParamSpec, value, error: str) -> None:
    with pytest.raises(ValueError, match=error):
        spec.coerce(value)
