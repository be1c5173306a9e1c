"""Stand-in for ROS 2's `launch` (see ../README.md): LaunchDescription and a context."""


class LaunchContext:
    """The launch configurations (launch arguments) a description is evaluated in."""

    def __init__(self, configurations):
        self.launch_configurations = dict(configurations)


class LaunchDescription:
    """An ordered list of actions."""

    def __init__(self, entities):
        self.entities = list(entities)
