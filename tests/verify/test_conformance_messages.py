"""Conformance failures say which check failed, what it expected and what happened (tests/brokenblocks.py)."""

import re

import brokenblocks as broken
import pytest

from flowtact.errors import ConformanceError
from flowtact.testing import (
    CHECKS,
    check_chunking_invariance,
    check_config_yaml_roundtrip,
    check_deterministic,
    check_documented,
    check_inputs_not_mutated,
)
from flowtact.verify.conformance import example_of


def failure(check, cls) -> str:
    with pytest.raises(ConformanceError) as info:
        check(cls)
    return str(info.value)


def test_chunking_dependence_names_the_output_sample_chunking_and_both_values():
    msg = failure(check_chunking_invariance, broken.PerChunkOffset)
    assert msg.startswith("per_chunk_offset: chunking invariance: expected the same output, bit for bit")
    # whole: 0.5 * (x[1] - x[0]) at sample 1; fed one sample at a time every chunk starts at its own sample
    assert re.search(
        r"output 'y' differs at sample 1 \(t=0\.001 s\) when fed in chunks of 1: "
        r"expected 0\.0005005\d* \(whole\), got 0\.0$",
        msg,
    ), msg


def test_mutating_an_input_in_place_says_so_and_what_to_write_instead():
    msg = failure(check_inputs_not_mutated, broken.Doubles)
    assert msg.startswith(
        "doubles: inputs not mutated: expected the example's inputs to come out of a run unchanged;"
    )
    assert "step() tried to change an input in place when fed in chunks of 7" in msg
    assert "read-only" in msg and "x.data.copy()" in msg


def test_an_input_changed_behind_the_read_only_flag_is_caught_at_its_sample():
    msg = failure(check_inputs_not_mutated, broken.Sneaky)
    assert re.search(
        r"input 'x' was changed at sample 500: expected 0\.5005\d* \(as given\), got 0\.5$", msg
    ), msg


def test_nondeterminism_names_the_run_and_points_at_self_rng():
    msg = failure(check_deterministic, broken.NotSeeded)
    assert msg.startswith(
        "not_seeded: deterministic: expected two runs with seed 3 to give identical outputs;"
    )
    assert re.search(
        r"output 'y' differs at sample 0 \(t=0 s\) on the second run: expected (\d+)\.0 \(first run\)", msg
    )
    assert "self.rng" in msg


@pytest.mark.parametrize("cls", [broken.StaticExample, broken.AttributeExample], ids=lambda c: c.__name__)
@pytest.mark.parametrize("check", CHECKS, ids=lambda c: c.__name__.removeprefix("check_"))
def test_staticmethod_and_attribute_examples_are_accepted(cls, check):
    check(cls)


def test_a_plain_method_example_fails_saying_exactly_what_to_write():
    msg = failure(check_config_yaml_roundtrip, broken.PlainMethodExample)
    assert "plain_method_example: example: expected example to be a classmethod" in msg
    assert "PlainMethodExample.example is a plain method taking self" in msg
    assert "@classmethod\n    def example(cls) -> Example:" in msg
    assert "not callable" not in msg


@pytest.mark.parametrize(
    ("cls", "says"),
    [
        (broken.DictExample, "expected example() to return a flowtact.Example; it returned dict: {'params'"),
        (broken.WrongPortExample, "expected example inputs named after input ports (x); it feeds 'u'"),
        (broken.NoExample, "expected NoExample to provide example(); it has none; write it as"),
        (
            broken.BadParamsExample,
            "expected example params the block accepts; ConfigError: bad_params_example: 'gain'",
        ),
    ],
    ids=lambda v: v.__name__ if isinstance(v, type) else "",
)
def test_a_wrong_example_is_named_before_any_check_runs(cls, says):
    for check in CHECKS[:-1]:  # documented reads no example
        assert says in failure(check, cls)
    with pytest.raises(ConformanceError, match="example"):
        example_of(cls)


def test_a_parameter_without_doc_is_named():
    msg = failure(check_documented, broken.Undocumented)
    assert (
        msg
        == "undocumented: documented: expected a doc for every parameter: param(..., doc=...) on 'gain'; it has none"
    )


@pytest.mark.parametrize("check", CHECKS, ids=lambda c: c.__name__.removeprefix("check_"))
def test_every_check_passes_a_correct_block(check):
    check(broken.StaticExample)
