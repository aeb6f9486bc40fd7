"""Config validation: types, rules, did-you-mean, YAML round trip, generated invalid values."""

from dataclasses import dataclass
from typing import Literal

import pytest

from flowtact import Config, ConfigError, param


@dataclass(frozen=True)
class C(Config):
    window: int = param(5, doc="samples", ge=3, odd=True)
    tau_s: float = param(0.01, doc="time constant", gt=0)
    mode: Literal["causal", "centred"] = param("causal", doc="mode")
    weights: tuple[float, ...] = param((1.0, 2.0), doc="weights", min_len=1, max_len=3)
    limit: float | None = param(None, doc="optional", ge=0)
    flag: bool = param(False, doc="flag")

    def check(self):
        if self.window > 9 and self.mode == "causal":
            raise self.error("window", "must be <= 9 in causal mode")


@pytest.mark.parametrize(
    ("params", "message"),
    [
        ({"window": 4}, "'window' must be odd; got 4"),
        ({"window": 1}, "'window' must be >= 3; got 1"),
        ({"window": 5.0}, "'window' must be an integer; got 5.0"),
        ({"window": True}, "'window' must be an integer; got True"),
        ({"tau_s": 0}, "'tau_s' must be > 0; got 0"),
        ({"tau_s": "fast"}, "'tau_s' must be a number; got 'fast'"),
        ({"tau_s": float("nan")}, "'tau_s' must be a finite number"),
        (
            {"mode": "centered"},
            "'mode' must be one of 'causal', 'centred'; got 'centered' (did you mean 'centred'?)",
        ),
        ({"weights": []}, "at least 1 items"),
        ({"weights": [1, 2, 3, 4]}, "at most 3 items"),
        ({"weights": [1, "x"]}, "'weights' must be a number; got 'x'"),
        ({"weights": 3.0}, "'weights' must be a list of float"),
        ({"limit": -1}, "'limit' must be >= 0; got -1"),
        ({"flag": "yes"}, "'flag' must be true or false"),
        ({"windw": 5}, "unknown parameter 'windw' (did you mean 'window'?)"),
        ({"window": 11}, "'window' must be <= 9 in causal mode"),
    ],
)
def test_bad_values_are_rejected_with_one_template(params, message):
    with pytest.raises(ConfigError) as e:
        C.build(params, owner="sg (savgol)")
    assert str(e.value).startswith("sg (savgol): ")
    assert message in str(e.value)


def test_values_are_coerced_and_frozen():
    c = C.build({"tau_s": 1, "weights": [1, 2], "limit": 3})
    assert c.tau_s == 1.0 and isinstance(c.tau_s, float)
    assert c.weights == (1.0, 2.0)
    assert C.build(c.to_dict()) == c
    with pytest.raises(AttributeError):
        c.tau_s = 2.0  # type: ignore[misc]


def test_generated_invalid_values_are_all_rejected():
    seen = set()
    for field, bad in C.invalid_values():
        seen.add(field)
        with pytest.raises(ConfigError):
            C.build({field: bad})
    assert seen == {"window", "tau_s", "mode", "weights", "limit", "flag"}


def test_fields_info_documents_every_field():
    info = {f.name: f for f in C.fields_info()}
    assert info["window"].rules == ">= 3, odd"
    assert info["mode"].type == "'causal' | 'centred'"
    assert info["weights"].default == [1.0, 2.0]
