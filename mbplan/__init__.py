"""mbplan: trajectory optimization of multi-body robots on matrix Lie groups.

The user API: describe the problem once (:class:`OCP` with a :class:`Scene` and residuals from
:mod:`mbplan.residuals`), :func:`plan` it with any method, :func:`verify` the result, save it;
or write it as a task file (:func:`load_task`, ``mbplan plan TASK.toml``).
"""

from mbplan import residuals
from mbplan.errors import InfeasibleRequestError, InputError, MbplanError, RobotModelError
from mbplan.ocp import OCP, Scene
from mbplan.planning.solve import METHODS, plan
from mbplan.results import PlanResult, load_npz, save_npz
from mbplan.robots import FreeBody, Robot, load_robot
from mbplan.taskfile import Task, load_task
from mbplan.verification import Verification, verify
from mbplan.workspace import Workspace

__all__ = [
    "METHODS",
    "OCP",
    "FreeBody",
    "InfeasibleRequestError",
    "InputError",
    "MbplanError",
    "PlanResult",
    "Robot",
    "RobotModelError",
    "Scene",
    "Task",
    "Verification",
    "Workspace",
    "load_npz",
    "load_robot",
    "load_task",
    "plan",
    "residuals",
    "save_npz",
    "verify",
]
__version__ = "0.1.0"
