"""The block contract is written once: ports derive specs, render their own docs, specs() is pure,
and block modules take what the framework gives them from one import (issue 32, Deliver 3)."""

from __future__ import annotations

import ast
import copy
import inspect
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import flowtact.api as ft
from flowtact.catalog.blocks import block_names, load_block
from flowtact.help.describe import describe_block
from flowtact.testing import infer_specs
from flowtact.verify.conformance import example_of

ROOT = Path(__file__).resolve().parent.parent
PORTS_SECTION = re.compile(r"^\s*Ports\s*\n\s*-{3,}\s*$", re.M)


def _section(text: str, title: str) -> str:
    return text.split(f"\n{title}:\n", 1)[1].split("\n\n", 1)[0]


@pytest.mark.parametrize("name", block_names())
def test_the_rendering_lists_every_declared_port_with_its_doc(name):
    cls = load_block(name)
    text = describe_block(cls, width=100)
    for title, ports in (("Inputs", cls.inputs), ("Outputs", cls.outputs)):
        section = _section(text, title)
        listed = re.findall(r"^  ([\w]+) ", section, re.M)
        assert listed == list(ports), (title, listed)
        for port in ports.values():  # the doc text given on the Port, rendered (wrapped) under it
            first_words = " ".join(port.doc.replace("``", "").split()[:4])
            assert first_words in " ".join(section.split()), (port.doc, section)


@pytest.mark.parametrize("name", block_names())
def test_no_block_docstring_repeats_its_ports(name):
    cls = load_block(name)
    assert not PORTS_SECTION.search(inspect.cleandoc(cls.__doc__ or "")), f"{name}: a Ports section"


def test_the_rendering_shows_what_the_declaration_derives():
    text = describe_block(load_block("fingertip_force"), width=100)
    assert "phi          float64 shape (3, 3), units rad, with a nominal rate, same rate as fsr" in text
    assert "f            float64 shape (3,), units N, at the rate of fsr, labels thumb, index, middle" in text
    nlif = describe_block(load_block("nlif"), width=100)
    assert "spikes       events, int64 shape (), units 1" in nlif  # n_units: n, or len(models): its specs()
    assert "len(models)" in " ".join(nlif.split())
    grasp = describe_block(load_block("grasp_sim"), width=100)
    assert "categories from object_names" in grasp
    scan = describe_block(load_block("braille_scan"), width=100)
    assert "at rate_hz (a parameter), labels r0c0, r0c1, r0c2 … r5c3 (24)" in scan  # long lists shortened


def _state(block: ft.Block) -> dict[str, Any]:
    """What a block holds: each attribute's identity and, for containers, a copy of its content."""
    return {
        k: (id(v), copy.copy(v) if isinstance(v, (dict, list, set)) else None) for k, v in vars(block).items()
    }


def _same(a: dict[str, Any], b: dict[str, Any]) -> bool:
    if a.keys() != b.keys():
        return False
    for k in a:
        (ida, ca), (idb, cb) = a[k], b[k]
        if ida != idb:
            return False
        if ca is not None and (ca.keys() != cb.keys() if isinstance(ca, dict) else len(ca) != len(cb)):
            return False
    return True


@pytest.mark.parametrize("name", block_names())
def test_specs_changes_nothing_on_the_block(name):
    cls = load_block(name)
    ex = example_of(cls)
    block = cls(**ex.params)
    inputs = infer_specs(block, ex.inputs, ex.rate_hz, ex.units)
    before = _state(block)
    first = block.specs(inputs)
    assert _same(before, _state(block)), (
        f"{name}: specs() changed {set(vars(block)) ^ set(before) or 'state'}"
    )
    assert block.specs(inputs) == first  # and asking again gives the same answer
    assert _same(before, _state(block))
    if isinstance(block, ft.Source):  # the end is asked at compile time too, also without binding
        assert block.ends_at(inputs) == block.ends_at(inputs)
        assert _same(before, _state(block))


def test_a_block_that_kept_state_in_specs_is_caught():
    class Leaky(ft.Block):
        outputs = {"y": ft.Port()}
        inputs = {"x": ft.Port()}

        def specs(self, inputs):
            self._seen = True
            return super().specs(inputs)

    b = Leaky()
    before = _state(b)
    b.specs({"x": ft.StreamSpec(rate_hz=10.0)})
    assert not _same(before, _state(b))


# -- ports derive their specs -------------------------------------------------------------------------


@dataclass(frozen=True)
class _ToyConfig(ft.Config):
    n: int = ft.param(3, doc="channels", ge=1)
    rate_hz: float = ft.param(50.0, doc="output rate", gt=0)
    names: tuple[str, ...] = ft.param(("lo", "hi"), doc="states")


class _Toy(ft.Block):
    config_cls = _ToyConfig
    inputs = {"a": ft.Port(ndim=(0, 1)), "b": ft.Port(optional=True)}
    outputs = {
        "wide": ft.Port(shape=("n", 2), units="N", rate="b", labels=("p", "q", "r", "s", "t", "u")),
        "state": ft.Port(shape=(), units="1", rate="rate_hz", categories="names"),
        "same": ft.Port(units=None, labels=()),
        "spikes": ft.Port(dtype="int64", shape=(), units="1", events=True, n_units="n"),
        "inherit": ft.Port(),
    }


def test_outputs_derive_shape_rate_labels_and_categories_from_parameters_and_named_inputs():
    a = ft.StreamSpec(shape=(2,), units="V", rate_hz=1000.0, labels=("x", "y"))
    b = ft.StreamSpec(shape=(), units="V", rate_hz=250.0)
    out = _Toy(n=3).specs({"a": a, "b": b})
    assert out["wide"] == ft.StreamSpec(
        shape=(3, 2), units="N", rate_hz=250.0, labels=("p", "q", "r", "s", "t", "u")
    )
    assert out["state"] == ft.StreamSpec(shape=(), units="1", rate_hz=50.0, categories=("lo", "hi"))
    assert out["same"] == ft.StreamSpec(shape=(2,), units="V", rate_hz=1000.0)  # no labels: ()
    assert out["spikes"] == ft.StreamSpec(dtype="int64", shape=(), units="1", events=True, n_units=3)
    assert out["inherit"] == a  # what the port leaves open follows the first connected input
    assert _Toy(n=5).specs({"b": b, "a": a})["wide"].shape == (5, 2)  # a named input, not the first
    alone = _Toy(rate_hz=8.0, names=["on"]).specs({"a": a})
    assert alone["state"] == ft.StreamSpec(shape=(), units="1", rate_hz=8.0, categories=("on",))
    assert alone["wide"].rate_hz is None  # its rate follows 'b', left unconnected


def test_a_port_naming_no_parameter_says_so():
    class Typo(ft.Block):
        config_cls = _ToyConfig
        outputs = {"y": ft.Port(shape=("m",))}

    with pytest.raises(
        TypeError, match=r"a port's shape or n_units names 'm', which is no parameter of _ToyConfig"
    ):
        Typo().specs({})


def test_same_rate_is_checked_when_binding():
    fsr = ft.StreamSpec(shape=(3,), units="N", rate_hz=100.0)
    phi = ft.StreamSpec(shape=(3, 3), units="rad", rate_hz=50.0)
    with pytest.raises(ft.SpecError, match=r"'phi' is 50 Hz but 'fsr' is 100 Hz") as e:
        load_block("fingertip_force")().bind({"fsr": fsr, "phi": phi})
    assert e.value.port == "phi"
    out = load_block("fingertip_force")().bind({"fsr": fsr, "phi": phi.with_(rate_hz=100.0)})
    assert out["f"].rate_hz == 100.0 and out["f"].labels == ("thumb", "index", "middle")


def test_nlif_defaults_have_one_source():
    from flowtact.blocks.spiking.nlif import NLIF_DEFAULTS, NlifConfig

    cfg = NlifConfig()
    assert all(getattr(cfg, k) == v for k, v in NLIF_DEFAULTS.items())
    assert not any(v is None for v in NLIF_DEFAULTS.values())
    for f in NlifConfig.fields_info():  # the default is rendered from the field, never said in prose
        assert "(default" not in f.doc and "default " not in f.doc, f.name
    assert np.array_equal(cfg.resolved()["tau_s"], [0.01])


# -- one import for block authors -----------------------------------------------------------------

#: Framework modules whose block-author names come through flowtact.api instead.
_KIT_MODULES = {
    "flowtact",
    "flowtact.block",
    "flowtact.chunk",
    "flowtact.params",
    "flowtact.streams.align",
    "flowtact.errors",
    "flowtact.finite",
    "flowtact.inputs.limits",
}


def test_block_modules_take_the_framework_from_one_import():
    offenders = []
    for path in sorted((ROOT / "blocks").rglob("*.py")):
        rel = path.relative_to(ROOT).as_posix()
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and node.level == 0 and node.module in _KIT_MODULES:
                kit = [a.name for a in node.names if a.name in ft.__all__]
                if kit:
                    offenders.append(f"{rel}:{node.lineno}: from {node.module} import {', '.join(kit)}")
    assert not offenders, "use `import flowtact.api as ft`:\n" + "\n".join(offenders)


def test_the_api_gives_the_frameworks_own_objects():
    import flowtact.block
    import flowtact.chunk
    import flowtact.params

    assert ft.Block is flowtact.block.Block and ft.Port is flowtact.block.Port
    assert ft.Chunk is flowtact.chunk.Chunk and ft.param is flowtact.params.param
    assert all(hasattr(ft, n) for n in ft.__all__)
