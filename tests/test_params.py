"""The strict parameter loader: ROS 2 parameter files, errors naming field and value."""
from __future__ import annotations

from pathlib import Path

import pytest

from moose.params import VEHICLE_LIMITS, ParamError, VehicleParams, build, read_ros_params


def test_table_one_defaults() -> None:
    p = VehicleParams()
    assert (p.m, p.Izz, p.J_wr, p.r, p.lf, p.lr) == (925.0, 617.0, 1.24, 0.301, 0.99, 0.71)
    assert (p.T_max, p.delta_max) == (200.0, 0.3)
    assert p.delta_rate_max == 1.0  # the road wheels' rate: Table I's 2618 rad/s is the EPS motor's 25 000 rpm
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


@pytest.mark.parametrize("field, value", [("T_max", 300.0), ("delta_max", 0.5), ("delta_rate_max", 2618.0),
                                          ("torque_rate_max", 1e5)])
def test_configuration_cannot_loosen_the_hard_limits(field: str, value: float) -> None:
    with pytest.raises(ParamError,
                       match=rf"vehicle\.{field} = .* is invalid: expected at most the vehicle's hard limit"):
        VehicleParams(**{field: value})
    tighter = VehicleParams(**{field: getattr(VEHICLE_LIMITS, field) / 2})
    assert getattr(tighter, field) == getattr(VEHICLE_LIMITS, field) / 2


def test_acceleration_limits_of_the_vehicle() -> None:
    # rear motors only: 2 T_max / r = 1329 N on 925 kg plus the wheels' 2 J / r^2 = 27.4 kg
    assert VehicleParams(mu=0.8).longitudinal_accel_limit == pytest.approx(
        2 * 200 / 0.301 / (925 + 2 * 1.24 / 0.301**2))
    # on ice the rear tyres limit first: mu F_zr = 0.1 * 925 * 9.81 * 0.99 / 1.7 = 528 N
    assert VehicleParams(mu=0.1).longitudinal_accel_limit == pytest.approx(
        0.1 * 925 * 9.81 * 0.99 / 1.7 / (925 + 2 * 1.24 / 0.301**2))
    assert VehicleParams(mu=0.33).lateral_accel_limit == pytest.approx(0.33 * 9.81)
