"""The shipped bags (bags/) hold a complete run, readable by independent decoders.

Every message of every shipped bag is decoded twice: by ``mcap-ros2-support`` (Foxglove's decoder, from
the definitions embedded in the file) and by ``rosbags``' AnyReader (also from the embedded definitions,
not from our type store), and both counts equal the counts in ``metadata.yaml``.  The bags carry what a
viewer and a replay need (TF, markers, actuator commands, diagnostics, /clock), the sensor frames as
transient-local /tf_static, and the run's parameters, with which ``moose bag replan`` reproduces the
recorded plans.
"""
from __future__ import annotations

from collections import Counter
from pathlib import Path

import pytest
import yaml

ROOT = Path(__file__).resolve().parents[1]
BAGS = sorted(p for p in (ROOT / "bags").iterdir() if (p / "metadata.yaml").is_file())
COMPLETE = {"/clock", "/tf", "/tf_static", "/planning/markers", "/control/actuator_command", "/control/reference",
            "/diagnostics", "/vehicle/odom", "/perception/state", "/perception/threat", "/planning/blend"}


def _metadata(bag: Path) -> dict:
    return yaml.safe_load((bag / "metadata.yaml").read_text(encoding="utf-8"))["rosbag2_bagfile_information"]


def test_there_are_shipped_bags_and_they_stay_small() -> None:
    assert len(BAGS) >= 2
    for bag in BAGS:
        assert sum(f.stat().st_size for f in bag.iterdir()) < 4_000_000, bag


@pytest.mark.parametrize("bag", BAGS, ids=lambda p: p.name)
def test_every_message_decodes_with_mcap_ros2_and_rosbags(bag: Path) -> None:
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory
    from rosbags.highlevel import AnyReader

    expected = {t["topic_metadata"]["name"]: t["message_count"] for t in _metadata(bag)["topics_with_message_count"]}
    by_mcap: Counter = Counter()
    for file in sorted(bag.glob("*.mcap")):
        with open(file, "rb") as stream:
            for _schema, channel, _message, decoded in make_reader(stream, decoder_factories=[DecoderFactory()]) \
                    .iter_decoded_messages():
                assert decoded is not None
                by_mcap[channel.topic] += 1
    by_rosbags: Counter = Counter()
    with AnyReader([bag]) as reader:  # types from the bag's own definitions
        for connection, _t, raw in reader.messages():
            reader.deserialize(raw, connection.msgtype)
            by_rosbags[connection.topic] += 1
    assert dict(by_mcap) == dict(by_rosbags) == expected
    assert COMPLETE <= set(expected), COMPLETE - set(expected)


@pytest.mark.parametrize("bag", BAGS, ids=lambda p: p.name)
def test_frames_markers_and_qos_are_there(bag: Path) -> None:
    from moose_ros.bag import read_bag

    offered = {t["topic_metadata"]["name"]: t["topic_metadata"]["offered_qos_profiles"]
               for t in _metadata(bag)["topics_with_message_count"]}
    assert offered["/tf_static"][0]["durability"] == "transient_local"
    assert offered["/planning/markers"][0]["reliability"] == "reliable"
    frames, static, namespaces = set(), set(), set()
    for m in read_bag(bag, ["/tf", "/tf_static", "/planning/markers"]):
        if m.topic == "/planning/markers":
            namespaces |= {(mk.ns, mk.action) for mk in m.msg.markers}
        else:
            (frames if m.topic == "/tf" else static).update(
                (x.header.frame_id, x.child_frame_id) for x in m.msg.transforms)
    assert frames == {("odom", "base_link"), ("odom", "base_link_truth")}
    assert static == {("base_link", "imu"), ("base_link", "gps")}
    drawn = {ns for ns, action in namespaces if action == 0}
    assert drawn == {"danger_zone", "danger_zone_width", "mpc", "msf", "blend"}


@pytest.mark.slow
@pytest.mark.parametrize("bag", BAGS, ids=lambda p: p.name)
def test_replan_uses_the_runs_parameters(bag: Path, tmp_path: Path) -> None:
    from matplotlib.image import imread

    from moose.config import load_config
    from moose_ros.bag import plot_replan, replan
    from moose_ros.bag.params import read_run_parameters

    run = read_run_parameters(bag)
    assert run is not None and bag.name.startswith(f"{run.scenario.name}_{run.planner}")
    assert run.config.vehicle.mu == run.scenario.mu  # the road of the run, not the file's default
    replanned = replan(bag)
    summary = replanned["summary"]
    # the plot: three panels of 7 x 7 inches at 110 dpi, in a folder it makes
    assert imread(plot_replan(replanned["rows"], tmp_path / "plots" / "replan.png")).shape == (770, 770, 4)
    assert summary["parameters"] == "bag"
    if "graph" not in bag.name:  # a lockstep run is reproduced to round-off
        assert summary["rms_ay"] < 1e-9 and summary["rms_weight"] < 1e-9 and summary["mpc_status_agreement"] == 1.0
    else:  # a graph run: the same planners on what the nodes received (timing may differ by a sample)
        assert summary["rms_ay"] < 0.5
    default = replan(bag, load_config())["summary"]  # the default configuration's road is another one
    assert default["parameters"] == "given" and default["road_mu"] != run.config.vehicle.mu


def test_an_unfinished_bag_still_gives_its_run_parameters(tmp_path: Path) -> None:
    """A bag cut off (its recorder killed: no metadata.yaml, the file ending mid-record) still names its run: the
    recorder writes the ``moose`` metadata record right after the header, and the reader reads records up to the
    cut.  A file cut before that record has none (``None``: recorded without them)."""
    from moose_ros.bag.params import read_run_parameters

    bag = ROOT / "bags" / "paper_v5_tau3_combined"
    whole = read_run_parameters(bag)
    assert whole is not None and whole.scenario.name == "paper_v5_tau3" and whole.planner == "combined"
    data = next(bag.glob("*.mcap")).read_bytes()
    for kept in (len(data), len(data) // 2, len(data) // 100):
        cut = tmp_path / f"cut_{kept}"
        cut.mkdir()
        (cut / "run_0.mcap").write_bytes(data[:kept])
        assert read_run_parameters(cut) == whole, kept
        assert read_run_parameters(cut / "run_0.mcap") == whole, kept  # the file itself
    (cut / "run_0.mcap").write_bytes(data[:100])
    assert read_run_parameters(cut) is None


def test_damaged_run_parameters_are_named(tmp_path: Path) -> None:
    from moose_ros.bag.errors import BagError
    from moose_ros.bag.params import RunParameters, read_run_parameters

    whole = read_run_parameters(ROOT / "bags" / "paper_v5_tau3_combined")
    assert whole is not None
    strings = whole.as_strings()
    assert RunParameters.from_strings(strings, "bag x") == whole
    with pytest.raises(BagError, match=r"^bag x: run parameters lack 'moose.seed'$"):
        RunParameters.from_strings({k: v for k, v in strings.items() if k != "moose.seed"}, "bag x")
    with pytest.raises(BagError, match=r"^bag x: run parameters are unreadable: moose.planner = 'fast' is invalid"):
        RunParameters.from_strings({**strings, "moose.planner": "fast"}, "bag x")
    unreadable = r"^bag x: run parameters are unreadable: invalid literal for int\(\) with base 10: 'zero'$"
    with pytest.raises(BagError, match=unreadable):
        RunParameters.from_strings({**strings, "moose.seed": "zero"}, "bag x")
    (tmp_path / "metadata.yaml").write_text("rosbag2_bagfile_information: [1, 2\n", encoding="utf-8")
    with pytest.raises(BagError, match=r"metadata.yaml is unreadable"):
        read_run_parameters(tmp_path)


def test_birdseye_view_draws_a_shipped_bag_and_refuses_one_without_markers(tmp_path: Path) -> None:
    import subprocess
    import sys

    from moose_ros.bag import BagError, BagWriter, plot_birdseye, read_bag
    from moose_ros.interfaces import from_rosbags

    out = plot_birdseye(BAGS[0], tmp_path / "view.png")
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    odom_only = tmp_path / "odom_only"
    writer = BagWriter(odom_only)
    for m in read_bag(BAGS[0], ["/vehicle/odom"]):
        writer.write(m.topic, m.type_name, m.timestamp_ns, bytes(from_rosbags(m.msg, m.type_name).serialize()))
    writer.close()
    with pytest.raises(BagError, match="/planning/markers"):
        plot_birdseye(odom_only, tmp_path / "none.png")
    cli = subprocess.run([sys.executable, "-m", "moose.cli", "bag", "view", str(odom_only),
                          "-o", str(tmp_path / "x.png")], capture_output=True, text=True, timeout=60)
    assert cli.returncode == 2 and cli.stderr.startswith("moose: error:") and "Traceback" not in cli.stderr
