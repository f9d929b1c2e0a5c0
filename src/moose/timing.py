"""The car's timing: its latency chain as named profiles, the delay mechanics that the lockstep loop and the node
graph share, the compute-time budget, and delay compensation (docs/design.md, "Closed loop and rates").

The semantics, one place for :mod:`moose.simulation` and the node graph (``timing`` of the configuration,
:class:`moose.schema.TimingParams`, every value a whole number of motion-control periods):

* **sensor delay** d_s: a sample the sensors hand over at t reaches the observer at t + d_s, stamped with its own
  time (:class:`DelayLine`, on the world's side: the lockstep loop between the sensors and the observer; the graph's
  simulator when it publishes samples or sends sensor frames);
* **planning delay** d_p: a planning instant at t plans from what is known at t; its blend and FBL reference act from
  t + d_p, the previous plan's held acceleration until then (a :class:`DelayLine` inside the core's planning step,
  :class:`moose.planner.step.PlanningStep`, which the lockstep loop and the ``weight_fbl`` node both run).  It is also
  the simulated compute time a lockstep run checks the MPC's budget against (:func:`over_budget`): a lockstep outcome
  never depends on the wall clock;
* **command delay** d_c: a command computed at t acts on the actuators from t + d_c and is held until the next one
  acts (:class:`CommandHold`, on the world's side: the lockstep loop before the plant; the graph's simulator or the
  vehicle-ECU emulator).

Delays are counted in motion-control ticks (10 ms): every consumer (observer, detector, planning step, FBL, motion
control) runs on that tick, so a finer delay would be rounded up by its consumer, and the CAN frame periods are
multiples of it.  A time t is the tick round(t / period).

**Profiles** (:func:`profile`): ``ideal`` is all zero (the lockstep loop as it was, bit for bit); ``car`` is the
FPEV2-Kanon's chain, each hop of which is read from config/kanon.dbc (:func:`car_chain`).

**Compensation** (``timing.compensate``, :func:`predict`, :func:`compensated_input`): the planners plan, and the FBL
commands, from the state predicted to the instant their output acts on the car, on the planners' kinematic model
eq. (skin) driven by the accelerations known to be in flight (:class:`AccelSchedule`), as Autoware's MPC predicts its
initial state through its buffer of commands over ``input_delay``.
"""
from __future__ import annotations

import dataclasses
import hashlib
import importlib.metadata
import json
import math
import os
import tempfile
from collections import deque
from functools import lru_cache
from pathlib import Path
from typing import Any, Generic, Literal, Optional, TypeVar, get_args

import numpy as np

from .planner.kinematics import kinematic_step
from .resources import DBC_FILE, cache_dir
from .schema import TimingParams
from .signals import PlannerInput, StateEstimate, time_to_collision

T = TypeVar("T")

ProfileName = Literal["ideal", "car"]
PROFILES: tuple[str, ...] = get_args(ProfileName)
"""The named latency chains (``--timing``)."""

GRID_S = 0.01
"""The grid the car's chain is rounded to (s): the motion-control tick of the shipped configuration and the period
of the DBC's control frames."""
PAPER_SQP_SOLVE_S = 1.5e-3
"""The paper baseline's time per plan at Table II's caps on this project's reference host (s): the 99th percentile of
``MpcPlanner.plan`` with ``mpc.solver: paper_sqp`` over the nine paper cases, combined planner, 10 s each, three
times (1,512 plans; p99 1.40–1.52 ms, median 0.64–0.67 ms, load average 0.7; the few slower plans, up to 17 ms, are
the shared host's scheduling, which the planning computer's real-time OS does not have)."""
HOST_CLOCK_HZ = 2.596e9
"""The clock of the host :data:`PAPER_SQP_SOLVE_S` was measured on (AMD EPYC, /proc/cpuinfo)."""
MICROLABBOX_CLOCK_HZ = 2.0e9
"""The paper's planning computer: dSPACE MicroLabBox, NXP QorIQ P5020 at 2 GHz (the paper, Sec. VI)."""


@dataclasses.dataclass(frozen=True)
class Hop:
    """One asynchronous periodic CAN hop: a frame period plus the frame's time on the wire."""

    frames: tuple[str, ...]
    period_s: float
    """The frames' common ``GenMsgCycleTime`` (s)."""
    wire_s: float
    """The longest of the frames' worst-case transmission times at the bus's ``Baudrate`` (s)."""

    @property
    def latency_s(self) -> float:
        """Expected latency (s): the wait for the sender's next frame (uniform over a period, mean half of it), the
        wire, and the wait for the receiver's next cycle (another half period on average)."""
        return self.period_s + self.wire_s


@dataclasses.dataclass(frozen=True)
class CarChain:
    """Where the car profile's delays come from (:func:`car_chain`)."""

    sensors: Hop
    """IMU, wheel speeds and EPS angle to the observer."""
    commands: Hop
    """The steering and torque commands to the EPS and the motor ECUs."""
    solve_s: float
    """The paper baseline's solve time scaled to the MicroLabBox's clock (s)."""
    timing: TimingParams


def on_grid(value: float, up: bool = False) -> float:
    """``value`` (s) on the :data:`GRID_S` grid: rounded to the nearest point, or up."""
    steps = value / GRID_S
    return round(math.ceil(steps - 1e-9) if up else round(steps)) * GRID_S


@lru_cache(maxsize=1)
def car_chain() -> CarChain:
    """The FPEV2-Kanon's chain from config/kanon.dbc (its frames' ``GenMsgCycleTime`` and the bus's ``Baudrate``):

    * d_s = one hop of the sensor frames (IMU, WHEEL_SPEEDS, EPS_STATUS), to the nearest grid point;
    * d_c = one hop of the command frames (CMD_STEER, CMD_TORQUE), to the nearest grid point;
    * d_p = the paper baseline's solve time on the MicroLabBox (:data:`PAPER_SQP_SOLVE_S` scaled by the clocks),
      rounded up to the grid (the plan is ready at the next tick), plus the hop of the plan to the motion-control
      computer (the AutoBox, on the same bus: the DBC holds no frame for it, so it is given the command frames'
      period).
    """
    sensors, commands = car_hops()
    solve = PAPER_SQP_SOLVE_S * HOST_CLOCK_HZ / MICROLABBOX_CLOCK_HZ
    timing = TimingParams(sensor_delay_s=on_grid(sensors.latency_s), command_delay_s=on_grid(commands.latency_s),
                          planning_delay_s=on_grid(solve, up=True) + on_grid(commands.latency_s), compensate=False)
    return CarChain(sensors, commands, solve, timing)


SENSOR_FRAMES = ("IMU", "WHEEL_SPEEDS", "EPS_STATUS")
COMMAND_FRAMES = ("CMD_STEER", "CMD_TORQUE")
HOP_SOURCES = ("timing.py", "canbus/bridge.py", "canbus/busload.py", "canbus/codec.py")
"""The modules whose code turns the DBC into the hops: their text is part of the cached hops' key."""


def dbc_hops() -> tuple[Hop, Hop]:
    """The sensor and the command hop, read from config/kanon.dbc with its parser (cantools, python-can)."""
    from .canbus.bridge import cycle_time
    from .canbus.busload import worst_case_frame_bits
    from .canbus.codec import default_database

    db = default_database()
    baud = int(db.dbc.attributes["Baudrate"].value)

    def hop(names: tuple[str, ...]) -> Hop:
        wire = max(worst_case_frame_bits(db.get_message_by_name(n).length) for n in names) / baud
        return Hop(names, cycle_time(db, *names), wire)

    return hop(SENSOR_FRAMES), hop(COMMAND_FRAMES)


def hops_cache_path() -> Path:
    """Where the hops of the DBC are cached: ``$MOOSE_CACHE_DIR/timing/<key>.json``, the key a SHA-256 of the DBC's
    bytes, the text of :data:`HOP_SOURCES` and the parser's version, so a changed file or code never finds another's
    hops."""
    digest = hashlib.sha256(DBC_FILE.read_bytes() + importlib.metadata.version("cantools").encode())
    here = Path(__file__).parent
    for name in HOP_SOURCES:
        digest.update((here / name).read_bytes())
    return cache_dir() / "timing" / f"{digest.hexdigest()[:32]}.json"


def car_hops() -> tuple[Hop, Hop]:
    """:func:`dbc_hops`, from the disk cache when it holds them: a node process that only needs the delays of the
    ``car`` profile then loads neither cantools nor python-can (about 6 MB of each process's memory; docs/design.md,
    "Processes").  The cached numbers are the parsed ones bit for bit (JSON keeps a float's every digit); an
    unreadable or malformed entry is read from the DBC again and replaced, written whole (a temporary file renamed)."""
    path = hops_cache_path()
    try:
        cached = json.loads(path.read_text(encoding="utf-8"))
        hops = tuple(Hop(tuple(cached[k]["frames"]), cached[k]["period_s"], cached[k]["wire_s"])
                     for k in ("sensors", "commands"))
        if all(_valid_hop(h, frames) for h, frames in zip(hops, (SENSOR_FRAMES, COMMAND_FRAMES))):
            return hops[0], hops[1]
    except (OSError, ValueError, KeyError, TypeError):  # none yet, or not what this code writes: read the DBC
        pass
    sensors, commands = dbc_hops()
    text = json.dumps({"sensors": dataclasses.asdict(sensors), "commands": dataclasses.asdict(commands)})
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        with tempfile.NamedTemporaryFile("w", dir=path.parent, suffix=".json.partial", delete=False,
                                         encoding="utf-8") as handle:
            handle.write(text)
        os.replace(handle.name, path)
    except OSError:
        pass  # a read-only or full cache costs the next process the DBC's parser, nothing else
    return sensors, commands


def _valid_hop(hop: Hop, frames: tuple[str, ...]) -> bool:
    return (hop.frames == frames and all(type(v) is float and 0.0 < v < math.inf for v in (hop.period_s, hop.wire_s)))


def profile(name: str, compensate: bool = False) -> TimingParams:
    """The delays of the named profile (:data:`PROFILES`) with ``compensate``."""
    if name == "ideal":
        return TimingParams(sensor_delay_s=0.0, planning_delay_s=0.0, command_delay_s=0.0, compensate=compensate)
    if name == "car":
        return dataclasses.replace(car_chain().timing, compensate=compensate)
    raise ValueError(f"timing profile {name!r} is unknown: expected one of {', '.join(PROFILES)}")


def profile_name(timing: TimingParams) -> str:
    """The name of the profile whose delays ``timing`` has, or ``custom``."""
    for name in PROFILES:
        if profile(name, timing.compensate) == timing:
            return name
    return "custom"


def describe(timing: TimingParams) -> dict[str, Any]:
    """What a run's summary says about its timing: the profile's name and every value."""
    return {"profile": profile_name(timing), **dataclasses.asdict(timing)}


def over_budget(compute_time_s: float, budget_s: float) -> bool:
    """Whether a solve that took ``compute_time_s`` missed its ``budget_s``.  In lockstep the compute time is the
    timing model's (``timing.planning_delay_s``), never the wall clock's; a real-time graph measures it."""
    return compute_time_s > budget_s


class DelayLine(Generic[T]):
    """Items handed over at tick k come out at tick k + n (n = delay / period), in the order they went in."""

    def __init__(self, delay_s: float, period_s: float) -> None:
        self.period_s = period_s
        self.ticks = round(delay_s / period_s)
        """n: the delay in ticks."""
        self._queue: deque[tuple[int, T]] = deque()

    def push(self, t: float, item: T) -> None:
        """Hand ``item`` over at time ``t``."""
        self._queue.append((round(t / self.period_s) + self.ticks, item))

    def pop_due(self, t: float) -> list[T]:
        """The items due by time ``t`` (handed over at t − delay or before), oldest first; they leave the line."""
        now, queue, out = round(t / self.period_s), self._queue, []
        while queue and queue[0][0] <= now:
            out.append(queue.popleft()[1])
        return out

    def __len__(self) -> int:
        return len(self._queue)


class CommandHold(Generic[T]):
    """The actuators' end of the command path: a command computed at t acts from t + d_c and is held until the next
    one acts.  Until the first one arrives the actuators hold the first command (the car cruised under it before the
    run began), so a delay adds no start-up transient."""

    def __init__(self, delay_s: float, period_s: float) -> None:
        self._line: DelayLine[T] = DelayLine(delay_s, period_s)
        self._acting: Optional[T] = None

    def push(self, t: float, command: T) -> None:
        """The command computed at ``t``."""
        self._line.push(t, command)
        if self._acting is None:
            self._acting = command

    def acting(self, t: float) -> T:
        """The command acting at ``t`` (a command must have been pushed)."""
        due = self._line.pop_due(t)
        if due:
            self._acting = due[-1]
        if self._acting is None:
            raise ValueError("no command was pushed yet")
        return self._acting


class SteeringPredictor:
    """Compensation of the EPS loop (a Smith predictor): the steering angle a rate command computed at t will meet
    when it acts, at t + d_c, from the newest EPS measurement and the rate commands in flight.

    The EPS integrates its rate command, clipped to ±δ̇_max, and stops at ±δ_max (the plant's actuator law and the
    CAN guard's); a command computed at τ acts over [τ + d_c, τ + d_c + Δt).  From δ_meas measured at t_m:
    δ ← clip(δ + Δt · sat(r_i, δ̇_max), ±δ_max) for every command i computed in [t_m − d_c, t), in order.  With a
    noise-free sensor the prediction is the angle itself, and the loop K_δ (δ* − δ̂) then steers as it does without
    any delay, d_c later."""

    def __init__(self, delay_s: float, period_s: float, delta_max: float, rate_max: float) -> None:
        self.delay_s, self.period_s = delay_s, period_s
        self.delta_max, self.rate_max = delta_max, rate_max
        self._commands: deque[tuple[int, float]] = deque()

    def record(self, t: float, rate: float) -> None:
        """The rate command computed at ``t``."""
        self._commands.append((round(t / self.period_s), rate))

    def predict(self, delta: float, t_measured: float, t: float) -> float:
        """The angle at t + d_c from ``delta`` measured at ``t_measured``, for a command computed at ``t``."""
        first = round((t_measured - self.delay_s) / self.period_s)
        now = round(t / self.period_s)
        commands = self._commands
        while commands and commands[0][0] < first:
            commands.popleft()
        limit, rate_max, dt = self.delta_max, self.rate_max, self.period_s
        for tick, rate in commands:
            if tick >= now:
                break
            delta = min(max(delta + dt * min(max(rate, -rate_max), rate_max), -limit), limit)
        return delta


class AccelSchedule:
    """The global accelerations [v̇_X*, v̇_Y*] the car is believed to follow, each from the time it acts on the car
    (a plan's first acceleration from t + d_p + d_c): the inputs in flight that :func:`predict` integrates.
    Before the first entry the car keeps its velocity (lane keeping at the approach speed)."""

    def __init__(self) -> None:
        self._entries: deque[tuple[float, np.ndarray]] = deque()

    def add(self, t: float, accel: np.ndarray) -> None:
        """``accel`` acts on the car from ``t`` (entries come in time order)."""
        self._entries.append((t, np.asarray(accel, dtype=float)))

    def segments(self, t0: float, t1: float) -> list[tuple[float, float, np.ndarray]]:
        """(start, end, acceleration) covering [t0, t1] in order; entries that ended before t0 are forgotten
        (predictions never start earlier than the last one: estimates only move forward)."""
        entries = self._entries
        while len(entries) > 1 and entries[1][0] <= t0:
            entries.popleft()
        out: list[tuple[float, float, np.ndarray]] = []
        start, accel = t0, np.zeros(2)
        for t, a in entries:
            if t >= t1:
                break
            if t > start:
                out.append((start, t, accel))
                start = t
            accel = a
        out.append((start, t1, accel))
        return out


def predict(estimate: StateEstimate, t: float, schedule: AccelSchedule) -> StateEstimate:
    """``estimate`` carried forward to ``t`` on the planners' kinematic model eq. (skin), through the accelerations
    in flight (``schedule``); the identity when ``t`` is the estimate's own time.

    Over each piece of constant acceleration a = [a_X, a_Y] of length h, the planners' exact zero-order hold
    (:func:`moose.planner.kinematics.kinematic_step`):  p ← p + h v + h²/2 a,  v ← v + h a.  The body keeps its
    sideslip: the heading turns with the velocity's course χ = atan2(v_Y, v_X), θ ← θ + χ(t) − χ(t_e) (unchanged
    below 0.1 m/s, where χ is undefined), and the body velocities are the predicted global velocity in the predicted
    heading, [v_x, v_y] = R(−θ) [v_X, v_Y].  The yaw rate and the steering angle are held (the kinematic model has
    neither).
    """
    if t == estimate.t:
        return estimate
    x, y, vX, vY = estimate.x, estimate.y, estimate.vX, estimate.vY
    course = math.atan2(vY, vX)
    for t0, t1, a in schedule.segments(estimate.t, t):
        x, y, vX, vY = kinematic_step((x, y, vX, vY), (float(a[0]), float(a[1])), t1 - t0)
    theta = estimate.theta
    if math.hypot(vX, vY) > 0.1 and math.hypot(estimate.vX, estimate.vY) > 0.1:
        theta += math.atan2(vY, vX) - course
    c, s = math.cos(theta), math.sin(theta)
    return StateEstimate(t=t, x=x, y=y, theta=theta, vx=c * vX + s * vY, vy=-s * vX + c * vY, gamma=estimate.gamma,
                         delta=estimate.delta)


def compensated_input(inp: PlannerInput, t: float, schedule: AccelSchedule) -> PlannerInput:
    """The planners' input for a plan whose first acceleration acts on the car at ``t``: the estimate predicted to
    ``t`` (:func:`predict`), and the threat's time to collision τ measured from that state as the detector measures
    it (the obstacle, w, the side and the ego path are geometry; ν is left as the detector measured it)."""
    estimate = predict(inp.estimate, t, schedule)
    threat = inp.threat
    if threat is not None:
        threat = dataclasses.replace(threat, t=t, tau=time_to_collision(threat.obstacle.x_min - estimate.x,
                                                                         estimate.vx))
    return dataclasses.replace(inp, t=t, estimate=estimate, threat=threat)
