"""Task files: a hand-written TOML description of a planning task, read into an
:class:`~mbplan.OCP` and solver settings (:func:`load_task`; ``mbplan plan TASK.toml``)."""

from mbplan.taskfile.task import Task, load_task

__all__ = ["Task", "load_task"]
