"""moose: emergency collision avoidance for a sudden static obstacle (the moose test).

After "Dodging the Moose: Experimental Insights in Real-Life Automated Collision Avoidance":
the pure core (model, maneuver table, planners, control, estimation, detection, lockstep
simulation, metrics); the ROS 2 node graph lives in the separate ``moose_ros`` package.
"""
