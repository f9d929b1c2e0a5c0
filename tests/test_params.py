"""The strict parameter loader: ROS 2 parameter files, errors naming field and value."""
from __future__ import annotations

from pathlib import Path

import pytest

from moose.params import ParamError, VehicleParams, build, read_ros_params


def test_table_one_defaults() -> None:
    p = VehicleParams()
    assert (p.m, p.Izz, p.J_wr, p.r, p.lf, p.lr) == (925.0, 617.0, 1.24, 0.301, 0.99, 0.71)
    assert (p.T_max, p.delta_max, p.delta_rate_max) == (200.0, 0.3, 2618.0)
    assert (p.Cx, p.Bx, p.Cy, p.By) == (1.5, 8.0, 1.4057, 7.1138)
    # static loads add up to the weight and balance the moments about the CoG
    assert p.Fzf + p.Fzr == pytest.approx(p.m * p.g)
    assert p.Fzf * p.lf == pytest.approx(p.Fzr * p.lr)


def test_build_accepts_ints_for_floats_and_rejects_the_rest() -> None:
    assert build(VehicleParams, {"m": 1000}, "vehicle").m == 1000.0
    with pytest.raises(ParamError, match=r"vehicle.m = 'heavy' is invalid: expected a number"):
        build(VehicleParams, {"m": "heavy"}, "vehicle")
    with pytest.raises(ParamError, match=r"vehicle.mass = 1 is unknown"):
        build(VehicleParams, {"mass": 1}, "vehicle")
    with pytest.raises(ParamError, match=r"vehicle.mu = -0.5 is invalid: expected a positive number"):
        build(VehicleParams, {"mu": -0.5}, "vehicle")
    with pytest.raises(ParamError, match=r"vehicle.m = True"):
        build(VehicleParams, {"m": True}, "vehicle")
    with pytest.raises(ParamError, match=r"vehicle.m = nan"):
        build(VehicleParams, {"m": float("nan")}, "vehicle")


def test_ros_parameter_file_wildcard_and_node_sections(tmp_path: Path) -> None:
    path = tmp_path / "p.yaml"
    path.write_text(
        "/**:\n  ros__parameters:\n    vehicle: {m: 900.0, mu: 0.8}\n"
        "observer:\n  ros__parameters:\n    vehicle: {mu: 0.5}\n"
    )
    assert read_ros_params(path) == {"vehicle": {"m": 900.0, "mu": 0.8}}
    assert read_ros_params(path, "observer") == {"vehicle": {"m": 900.0, "mu": 0.5}}
    assert read_ros_params(path, "/observer") == {"vehicle": {"m": 900.0, "mu": 0.5}}


@pytest.mark.parametrize(
    "text, needle",
    [
        ("a: [1, 2\n", "is not valid YAML"),
        ("- 1\n", "expected a mapping of node names"),
        ("/**:\n  params: {}\n", "section '/**' has no ros__parameters"),
        ("/**:\n  ros__parameters: 3\n", "/**.ros__parameters = 3 is not a mapping"),
    ],
)
def test_bad_parameter_files(tmp_path: Path, text: str, needle: str) -> None:
    path = tmp_path / "p.yaml"
    path.write_text(text)
    with pytest.raises(ParamError) as info:
        read_ros_params(path)
    assert needle in str(info.value)


def test_missing_file_is_a_clear_error(tmp_path: Path) -> None:
    with pytest.raises(ParamError, match="cannot be read"):
        read_ros_params(tmp_path / "missing.yaml")
