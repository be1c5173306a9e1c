"""Stand-in for `launch.substitutions`: LaunchConfiguration only."""


class LaunchConfiguration:
    """The value of a launch argument, read when the description is evaluated."""

    def __init__(self, name):
        self.name = name

    def perform(self, context):
        if self.name not in context.launch_configurations:
            raise KeyError(f"launch configuration {self.name!r} is not declared")
        return context.launch_configurations[self.name]


def perform(value, context):
    """A string, a substitution, or a list of them, as launch joins them."""
    if isinstance(value, str):
        return value
    if isinstance(value, LaunchConfiguration):
        return value.perform(context)
    if isinstance(value, (list, tuple)):
        return ''.join(perform(v, context) for v in value)
    raise TypeError(f"not a substitution the stand-in knows: {value!r}")
