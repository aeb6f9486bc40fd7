"""The conformance suite of flowtact.testing, run on every registered block."""

import pytest

from flowtact.catalog.blocks import block_names, load_block
from flowtact.testing import CHECKS


@pytest.mark.parametrize("check", CHECKS, ids=lambda c: c.__name__.removeprefix("check_"))
@pytest.mark.parametrize("name", block_names())
def test_block_conformance(name, check):
    check(load_block(name))
