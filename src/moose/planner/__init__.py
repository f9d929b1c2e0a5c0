"""The planning chain of Fig. 3: two planners, the weight function that blends their plans, and the
feedback linearization that turns the blend into the reference of motion control.

* :class:`Planner` — what a planner is to the rest of the chain (the MPC and the MSF planner);
* :mod:`moose.planner.kinematics` — eq. (skin): the one zero-order-hold step and rollout;
* :mod:`moose.planner.mpc` — the MPC planner on the kinematic model (Sec. IV-B) and its solvers;
* :mod:`moose.planner.msf` — the maximum-steering feed-forward planner (Sec. IV-A);
* :mod:`moose.planner.baseline` — the baselines ``aeb`` and ``max_steer``, in the MSF planner's slot;
* :mod:`moose.planner.weight` — the weight function (Sec. IV);
* :mod:`moose.planner.fbl` — the feedback linearization, eq. (FBL);
* :mod:`moose.planner.step` — one planning instant: every place that plans goes through it.

The package itself imports nothing heavy: the ``weight_fbl`` node uses the step, the weight function
and the FBL without loading CasADi or the planners.
"""
from __future__ import annotations

from typing import Optional, Protocol

from ..schema import PlannerMode
from ..signals import PlannerInput, PlanResult, Threat

MODE_PLANNERS: dict[str, tuple[str, ...]] = {
    "combined": ("mpc", "msf"), "mpc": ("mpc",), "msf": ("msf",), "aeb": ("msf",), "max_steer": ("msf",)}
"""The planner slots each mode uses: ``mpc``, the optimizing planner (the ``mpc_planner`` node), and ``msf``, the
feed-forward planner (the ``msf_planner`` node), which runs the MSF planner or, in a baseline mode, the baseline
(:func:`moose.planner.baseline.feed_forward_planner`)."""


class Planner(Protocol):
    """A planner of Fig. 3: :class:`moose.planner.mpc.MpcPlanner` or :class:`moose.planner.msf.MsfPlanner`, or a
    baseline of :mod:`moose.planner.baseline`.

    The planning step (:class:`moose.planner.step.PlanningStep`) and the planner nodes of the graph
    use a planner only through these two methods.
    """

    def plan(self, inp: PlannerInput) -> PlanResult:
        """The plan at one planning instant: N_p accelerations [v̇_X, v̇_Y] and the states they predict
        (:func:`moose.planner.kinematics.kinematic_rollout`), with the planner's status."""
        ...

    def reset(self) -> None:
        """Forget what earlier plans left behind: the next plan is the one a new planner would make."""
        ...



def commanded_steering(mode: PlannerMode, plan: Optional[PlanResult], threat: Optional[Threat],
                       delta_max: float) -> Optional[float]:
    """δ* that the planner of ``mode`` commands itself in place of the FBL's, or None (the FBL's δ* stands):
    ``max_steer`` while its plan acts on a threat (status ``ok``), full lock toward the evasion side, side · δ_max
    (:class:`moose.planner.baseline.MaxSteerPlanner`).  The planning step applies it, in lockstep and in the
    ``weight_fbl`` node alike, and holds it between planning instants."""
    if mode == "max_steer" and plan is not None and plan.status == "ok" and threat is not None:
        return float(threat.side) * delta_max
    return None


def commanded_speed(mode: PlannerMode, plan: Optional[PlanResult]) -> Optional[float]:
    """v_x* that the planner of ``mode`` commands itself in place of the FBL's, or None (the FBL's v_x* stands):
    ``aeb`` while braking (status ``ok``), 0, which the motion controller follows with the motors' full torque
    (:class:`moose.planner.baseline.AebPlanner`)."""
    if mode == "aeb" and plan is not None and plan.status == "ok":
        return 0.0
    return None
