"""The planning chain of Fig. 3: two planners, the weight function that blends their plans, and the
feedback linearization that turns the blend into the reference of motion control.

* :class:`Planner` — what a planner is to the rest of the chain (the MPC and the MSF planner);
* :mod:`moose.planner.kinematics` — eq. (skin): the one zero-order-hold step and rollout;
* :mod:`moose.planner.mpc` — the MPC planner on the kinematic model (Sec. IV-B) and its solvers;
* :mod:`moose.planner.msf` — the maximum-steering feed-forward planner (Sec. IV-A);
* :mod:`moose.planner.weight` — the weight function (Sec. IV);
* :mod:`moose.planner.fbl` — the feedback linearization, eq. (FBL);
* :mod:`moose.planner.step` — one planning instant: every place that plans goes through it.

The package itself imports nothing heavy: the ``weight_fbl`` node uses the step, the weight function
and the FBL without loading CasADi or the planners.
"""
from __future__ import annotations

from typing import Protocol

from ..signals import PlannerInput, PlanResult


class Planner(Protocol):
    """A planner of Fig. 3: :class:`moose.planner.mpc.MpcPlanner` or :class:`moose.planner.msf.MsfPlanner`.

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
