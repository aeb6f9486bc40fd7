"""The README's "Writing a block" example is complete: it passes the conformance suite and works."""

from __future__ import annotations

import re
import sys
import types
from pathlib import Path

import numpy as np
import pytest

from flowtact import Block, ConfigError, SpecError, StreamSpec
from flowtact.testing import CHECKS, run_offline

README = Path(__file__).resolve().parents[2] / "README.md"


def _readme_block() -> type[Block]:
    """The README's block, imported as a module would be (dataclasses look their module up)."""
    if "readme_contact" not in sys.modules:
        section = README.read_text().split("## Writing a block", 1)[1].split("\n## ", 1)[0]
        code = re.search(r"```python\n(.*?)```", section, re.S).group(1)  # type: ignore[union-attr]
        module = sys.modules["readme_contact"] = types.ModuleType("readme_contact")
        exec(compile(code, f"{README}#writing-a-block", "exec"), module.__dict__)  # the README's own code
    return sys.modules["readme_contact"].Contact


@pytest.mark.parametrize("check", CHECKS, ids=lambda c: c.__name__.removeprefix("check_"))
def test_the_readme_block_passes_the_conformance_suite(check):
    check(_readme_block())


def test_the_readme_block_holds_contact_between_its_thresholds():
    contact = _readme_block()
    f = np.array([[0.0, 0.25], [0.15, 0.15], [0.05, 0.3], [0.25, 0.05]])
    out = run_offline(contact(), f=f, units={"f": "N"}, chunk=1)["y"].data
    np.testing.assert_array_equal(out, [[0, 1], [0, 1], [0, 1], [1, 0]])
    with pytest.raises(ConfigError, match="'off_n' must be < on_n"):
        contact(on_n=0.1, off_n=0.2)
    with pytest.raises(SpecError, match="expects units 'N' but gets 'mN'"):
        contact().bind({"f": StreamSpec(units="mN", rate_hz=1000.0)})
