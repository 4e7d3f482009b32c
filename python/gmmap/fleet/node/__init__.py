"""The nodes: a robot node (`robot.RobotNode`) and its report (`report`), the ``gmmap robot``
process around it (`runner`) and the base station (`station`)."""
