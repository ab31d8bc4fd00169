"""Parameter descriptions shared by the estimators, the input gate, the ROS nodes and the CLI (ROS-free).

A :class:`ParamSpec` holds a parameter's default, description, range and whether it may change at run
time. Every default and range is written once, in the module that owns the parameter (the estimators'
``PARAMS``, :data:`riann_ros.gate.GATE_PARAMS`, the node base's own): the ROS node declares them from
the specs, the evaluator parses and tunes them through the specs.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

_BOOL_TEXT = {"true": True, "false": False, "yes": True, "no": False, "on": True, "off": False, "1": True, "0": False}


@dataclass(frozen=True)
class ParamSpec:
    """One parameter: what the node declares, the CLI parses and the evaluator can tune."""

    name: str
    default: float | int | bool | str | tuple[float, ...]
    description: str
    min: float | None = None
    max: float | None = None
    runtime: bool = False  # may change while running (validated), without a reset
    choices: tuple[str, ...] = ()  # allowed values of a string parameter (empty: any string)
    # a tuple default makes a fixed-length array of floats (ROS double array), each element within min/max

    def validate(self, value: Any) -> Any:
        """Return ``value`` converted to the parameter's type, or raise ``ValueError``.

        Integers are accepted for float parameters (``nominal_rate:=200``) and converted.
        """
        if isinstance(self.default, bool):
            if not isinstance(value, bool):
                raise ValueError(f"{self.name} must be a bool, got {value!r}")
            return value
        if isinstance(self.default, str):
            if not isinstance(value, str):
                raise ValueError(f"{self.name} must be a string, got {value!r}")
            if self.choices and value not in self.choices:
                raise ValueError(f"{self.name} must be one of {', '.join(self.choices)}, got {value!r}")
            return value
        if isinstance(self.default, tuple):
            return self._validate_array(value)
        return self._validate_number(value)

    def _validate_array(self, value: Any) -> tuple[float, ...]:
        n = len(self.default)  # type: ignore[arg-type]
        if isinstance(value, str | bytes) or not hasattr(value, "__len__") or len(value) != n:
            raise ValueError(f"{self.name} must be a list of {n} numbers, got {value!r}")
        return tuple(float(ParamSpec(self.name, 0.0, "", self.min, self.max)._validate_number(v)) for v in value)

    def _validate_number(self, value: Any) -> float | int:
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise ValueError(f"{self.name} must be a number, got {value!r}")
        if isinstance(self.default, int) and not float(value).is_integer():
            raise ValueError(f"{self.name} must be an integer, got {value!r}")
        v = float(value)
        if not math.isfinite(v):
            raise ValueError(f"{self.name} must be finite, got {value!r}")
        if self.min is not None and v < self.min:
            raise ValueError(f"{self.name}={v:g} is below its minimum {self.min:g}")
        if self.max is not None and v > self.max:
            raise ValueError(f"{self.name}={v:g} is above its maximum {self.max:g}")
        return int(v) if isinstance(self.default, int) else v

    def coerce(self, value: Any) -> Any:
        """``value`` as a user naturally writes it, converted to the parameter's type and validated.

        YAML and the ROS command line type a value by its spelling, so the same intent arrives as another
        type: ``200`` for a float, ``false`` (a bool) for ``use_mag``, ``"true"`` (a string, e.g. from a
        launch substitution) for a bool, ``[0, 0, 1]`` (integers) for a float array, ``NED`` for ``ned``.
        Accepted: for a float or integer parameter a number or a numeric string (an integer parameter
        only whole values); for a bool ``true``/``false``/``yes``/``no``/``on``/``off``/``1``/``0`` (any
        case) or the integers 1 and 0; for a string with choices any case of a choice, and ``true``/``false``
        given as bools where the choices contain them; for a free string any scalar (its text); for an array
        a list of numbers or its text (``"1,2,3"``). Anything else raises ``ValueError`` as :meth:`validate`.
        """
        if isinstance(self.default, bool):
            return self.validate(self._as_bool(value))
        if isinstance(self.default, str):
            return self.validate(self._as_str(value))
        if isinstance(self.default, tuple):
            if isinstance(value, str):
                return self.parse(value)
            return self.validate(list(value) if isinstance(value, list | tuple) else value)
        if isinstance(value, str):
            return self.parse(value)
        return self.validate(value)

    def _as_bool(self, value: Any) -> Any:
        if isinstance(value, str) and value.strip().lower() in _BOOL_TEXT:
            return _BOOL_TEXT[value.strip().lower()]
        if isinstance(value, int) and not isinstance(value, bool) and value in (0, 1):
            return bool(value)
        return value

    def _as_str(self, value: Any) -> Any:
        if isinstance(value, bool):
            value = "true" if value else "false"
        elif isinstance(value, int | float) and not self.choices:
            value = str(value)
        if isinstance(value, str) and self.choices and value not in self.choices:
            folded = {c.lower(): c for c in self.choices}
            value = folded.get(value.strip().lower(), value)
        return value

    def parse(self, text: str) -> Any:
        """The value of a command-line string (``"0.1"``, ``"true"``, ``"sensor_data"``), validated."""
        if isinstance(self.default, str):
            return self.validate(text)
        if isinstance(self.default, tuple):  # "1,2,3" or "[1, 2, 3]"
            parts = [t for t in text.strip().strip("[]").replace(" ", "").split(",") if t]
            try:
                return self.validate([float(t) for t in parts])
            except ValueError:
                raise ValueError(f"{self.name} must be {len(self.default)} comma-separated numbers, "
                                 f"got {text!r}") from None
        low = text.strip().lower()
        if isinstance(self.default, bool):
            if low not in ("true", "false"):
                raise ValueError(f"{self.name} must be true or false, got {text!r}")
            return low == "true"
        try:
            number = float(low)
        except ValueError:
            raise ValueError(f"{self.name} must be a number, got {text!r}") from None
        return self.validate(number)


def defaults(specs: tuple[ParamSpec, ...]) -> dict[str, Any]:
    """``{name: default}`` of a tuple of specs."""
    return {p.name: p.default for p in specs}


def find(specs: tuple[ParamSpec, ...], name: str) -> ParamSpec:
    """The spec called ``name`` (``KeyError`` otherwise)."""
    for p in specs:
        if p.name == name:
            return p
    raise KeyError(name)


def launch_overrides(arguments: dict[str, tuple[str, str]], texts: dict[str, str]) -> dict[str, Any]:
    """The launch arguments given (``texts``: name → the argument's text; empty = not given, the parameter file's
    value stands) as typed node parameters; ``arguments``: name → (type ``float`` | ``bool`` | ``str``,
    description), the launch files' ``PARAMETER_ARGUMENTS``. ValueError when a text does not parse."""
    out: dict[str, Any] = {}
    for name, (kind, _) in arguments.items():
        text = texts.get(name, "")
        if text == "":
            continue
        if kind == "float":
            out[name] = float(text)
        elif kind == "bool":
            if text.strip().lower() not in ("true", "false"):
                raise ValueError(f"{name} must be true or false, got {text!r}")
            out[name] = text.strip().lower() == "true"
        else:
            out[name] = text
    return out
