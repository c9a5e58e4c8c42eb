"""Exception classes: every user-facing failure names what is wrong."""


class MbplanError(Exception):
    """Base class of all mbplan errors."""


class InputError(MbplanError, ValueError):
    """Invalid user input: wrong shape, non-finite value, element not in the group, ..."""


class RobotModelError(MbplanError, ValueError):
    """A robot description that cannot be turned into a model (bad URDF, unsupported joint, ...)."""


class InfeasibleRequestError(MbplanError, ValueError):
    """A planning request that cannot be satisfied (start in collision, target out of reach, ...)."""


class WarmStartWarning(UserWarning):
    """A warm start that could not be built as asked and fell back to a simpler one."""
