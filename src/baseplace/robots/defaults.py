"""The robot a job uses when none is given: its one name outside the robot files' own specs.

A module of its own, so that the command line's ``--help`` and the jobs' input dataclasses name
the default without loading pinocchio (``baseplace.robots`` imports its models lazily).
"""

DEFAULT_ROBOT = "tiago"
"""Built-in robot of every job, command and service request that names none (:data:`~baseplace.robots.spec.BUILTIN_ROBOTS`)."""
