"""What ``moose.files.dump_yaml`` writes (bag metadata, the run's parameters in a bag, a sweep's configuration) reads
back as the same data, with libyaml's emitter as with PyYAML's own."""
from __future__ import annotations

import math
from pathlib import Path

import pytest
import yaml

from moose.config import config_as_ros_params, load_config
from moose.files import dump_yaml, load_yaml

ROOT = Path(__file__).resolve().parents[1]


def documents() -> list[object]:
    metadata = yaml.safe_load((ROOT / "bags" / "paper_v7_tau1.4_combined_graph" / "metadata.yaml").read_text())
    odd = {"z": [0.1, 1e-9, -0.0, 925.0, 2**53 + 1, math.pi], "a": {"yes": "yes", "null": None, "colon": "a: b",
                                                                   "long": "x " * 400, "lines": "one\ntwo\n"}}
    return [config_as_ros_params(load_config(None)), metadata, odd]


@pytest.mark.parametrize("document", documents(), ids=["config", "bag-metadata", "odd-values"])
def test_what_is_dumped_reads_back_the_same(document: object) -> None:
    for sort_keys in (False, True):
        text = dump_yaml(document, sort_keys=sort_keys)
        assert load_yaml(text, "dumped") == document


def test_keys_keep_their_order_unless_sorted() -> None:
    document = {"b": 1, "a": {"d": 2, "c": 3}}
    assert dump_yaml(document) == "b: 1\na:\n  d: 2\n  c: 3\n"
    assert dump_yaml(document, sort_keys=True) == "a:\n  c: 3\n  d: 2\nb: 1\n"
