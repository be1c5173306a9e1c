"""Stand-in for `launch.actions`: DeclareLaunchArgument and OpaqueFunction."""


class DeclareLaunchArgument:
    def __init__(self, name, default_value=None, description=''):
        self.name = name
        self.default_value = default_value
        self.description = description


class OpaqueFunction:
    """Calls `function(context)` when evaluated; it returns more actions."""

    def __init__(self, function, args=None, kwargs=None):
        self.function = function
        self.args = args or []
        self.kwargs = kwargs or {}
