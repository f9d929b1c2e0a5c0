"""What the tests of the MPC planner charge a solve against its time budget (``MpcPlanner(compute_time_s=…)``)."""

INSTANT = 0.0
"""No compute time: a test of *what* the MPC computes (its plan, its status) must not turn ``over_budget`` because a
loaded machine solved slowly (a CI beside other jobs did, at load 27).  How fast it solves is bench/bench_mpc.py's
question; the tests of ``over_budget`` itself give a budget of 1e-9 s and charge the wall time."""
