"""The car's timing: its latency chain as named profiles, the delay mechanics that the lockstep loop and the node
graph share, the compute-time budget, and delay compensation (docs/architecture.md, "Closed loop and rates").

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
import math
from collections import deque
from typing import Any, Generic, Literal, Optional, TypeVar, get_args

import numpy as np

from .car_chain import car_chain
from .planner.kinematics import kinematic_step
from .schema import TimingParams
from .signals import PlannerInput, StateEstimate, time_to_collision

T = TypeVar("T")

ProfileName = Literal["ideal", "car"]
PROFILES: tuple[str, ...] = get_args(ProfileName)
"""The named latency chains (``--timing``)."""

def profile(name: str, compensate: bool = False) -> TimingParams:
    """The delays of the named profile (:data:`PROFILES`) with ``compensate``."""
    if name == "ideal":
        return TimingParams(sensor_delay_s=0.0, planning_delay_s=0.0, command_delay_s=0.0, compensate=compensate)
    if name == "car":
        chain = car_chain()
        return TimingParams(sensor_delay_s=chain.sensor_delay_s, planning_delay_s=chain.planning_delay_s,
                            command_delay_s=chain.command_delay_s, compensate=compensate)
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
        self._first: Optional[T] = None
        """The first command, acting from its push and not yet handed out by :meth:`arrivals`."""

    def push(self, t: float, command: T) -> None:
        """The command computed at ``t``."""
        self._line.push(t, command)
        if self._acting is None:
            self._acting = command
            if self._line.ticks > 0:  # without a delay it comes out of the line at once
                self._first = command

    def arrivals(self, t: float) -> list[T]:
        """The commands that reach the actuators at ``t``, in order (the first one at once, then each d_c after it
        was computed): what an actuator that supervises its commands (the CAN guard, the ECUs) receives."""
        due = self._line.pop_due(t)
        if due:
            self._acting = due[-1]
        if self._first is not None:
            due.insert(0, self._first)
            self._first = None
        return due

    def acting(self, t: float) -> T:
        """The command acting at ``t`` (a command must have been pushed)."""
        self.arrivals(t)
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
