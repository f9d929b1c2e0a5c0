"""The planning chain of Fig. 3: two planners, the weight function that blends their plans, and the
feedback linearization that turns the blend into the reference of motion control.

* :mod:`moose.planner.kinematics` — eq. (skin): the one zero-order-hold step and rollout;
* :mod:`moose.planner.mpc` — the MPC planner on the kinematic model (Sec. IV-B) and its solvers;
* :mod:`moose.planner.msf` — the maximum-steering feed-forward planner (Sec. IV-A);
* :mod:`moose.planner.weight` — the weight function (Sec. IV);
* :mod:`moose.planner.fbl` — the feedback linearization, eq. (FBL);
* :mod:`moose.planner.step` — one planning instant: every place that plans goes through it.

The package itself imports nothing heavy: the ``weight_fbl`` node uses the step, the weight function
and the FBL without loading CasADi or the planners.
"""
