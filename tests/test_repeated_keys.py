"""A key given twice in one YAML mapping is an error, never a silent last-wins (the probe of issue 23): plain YAML
kept the second ``/**:`` section and dropped the first without a word, so a file that loosened a verdict limit in
one section and set the mass in another ran under the default limits; ``vehicle: {m: -5.0, m: 925.0}`` ran CLEAR.
And a bag whose ``metadata.yaml`` is garbage is read, and said so."""
from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from moose.files import load_yaml
from moose.params import ParamError, read_ros_params
from moose.scenario import load_scenario
from moose_ros.bag import ReadReport, bag_info
from moose_ros.parameters import check_parameter_file

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE_BAG = ROOT / "bags" / "paper_v7_tau1.4_combined"

TWO_SECTIONS = """\
/**:
  ros__parameters:
    verdict: {sideslip_max: 10.0}
/**:
  ros__parameters:
    vehicle: {m: 925.0}
"""


def test_a_section_given_twice_is_refused_by_every_reader(tmp_path: Path) -> None:
    path = tmp_path / "twice.yaml"
    path.write_text(TWO_SECTIONS)
    expected = r"'/\*\*' is given twice in one mapping \(lines 1 and 4\)"
    with pytest.raises(ParamError, match=expected):
        read_ros_params(path)  # moose simulate --config, bag replan --params
    with pytest.raises(ParamError, match=expected):
        check_parameter_file(path)  # moose launch --config, before a node starts
    path.write_text(TWO_SECTIONS.replace("\n/**:", "\nobserver:"))
    assert read_ros_params(path, "observer")["verdict"]["sideslip_max"] == 10.0  # two sections, each once: fine


@pytest.mark.parametrize("text", ["vehicle: {m: -5.0, m: 925.0}", "vehicle:\n  m: -5.0\n  m: 925.0"])
def test_a_key_given_twice_is_refused_on_one_line_or_two(tmp_path: Path, text: str) -> None:
    path = tmp_path / "key.yaml"
    path.write_text("/**:\n  ros__parameters:\n" + "".join(f"    {line}\n" for line in text.splitlines()))
    with pytest.raises(ParamError, match=rf"parameter file '{path}': 'm' is given twice"):
        read_ros_params(path)


def test_a_merge_key_may_still_be_overridden() -> None:
    assert load_yaml("base: &b {m: 1, n: 2}\nv:\n  <<: *b\n  m: 3\n", "x") == {"base": {"m": 1, "n": 2},
                                                                              "v": {"m": 3, "n": 2}}


def test_a_scenario_with_a_key_given_twice_is_refused(tmp_path: Path) -> None:
    text = (ROOT / "config" / "scenarios" / "paper_v6_w2.0.yaml").read_text()
    path = tmp_path / "s.yaml"
    path.write_text(text + "tau: 1.4\n")  # a second tau after the file's 3.0
    with pytest.raises(ParamError, match=r"scenario file .*: 'tau' is given twice in one mapping \(lines 7 and 14\)"):
        load_scenario(path)


def test_a_bag_whose_metadata_is_garbage_is_read_and_reported(tmp_path: Path) -> None:
    bag = tmp_path / "bag"
    shutil.copytree(EXAMPLE_BAG, bag)
    whole = bag_info(bag)
    (bag / "metadata.yaml").write_bytes(bytes(range(256)) * 4)  # not UTF-8, not YAML
    report = ReadReport(str(bag))
    info = bag_info(bag, report)
    assert {t: e["count"] for t, e in info["topics"].items()} == {t: e["count"] for t, e in whole["topics"].items()}
    assert not report.complete  # bag info / export exit 1
    assert any("metadata.yaml is unreadable (UnicodeDecodeError)" in line for line in report.losses())
    (bag / "metadata.yaml").unlink()  # no metadata at all (a single-file bag, a killed recorder): nothing to say
    report = ReadReport(str(bag))
    bag_info(bag, report)
    assert report.metadata == "" and report.complete
