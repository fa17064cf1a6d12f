"""The planner interface: what :meth:`setfleet.Run.serve` calls for every request."""

from __future__ import annotations

from typing import Any, Callable, Sequence, Union

from .layout import Action, Observation, as_action

__all__ = ["Planner", "FunctionPlanner", "as_planner", "Decision"]

#: What :meth:`Planner.decide` may return: an :class:`~setfleet.Action`, one yaw increment
#: (a number, rad) or a sequence of yaw increments (the first applied now).
Decision = Union[Action, float, Sequence[float]]


class Planner:
    """Base class of a guidance planner run outside the agents.

    Subclass it and implement :meth:`decide`. :meth:`setfleet.Run.serve` calls
    :meth:`reset` once before the run's first request, then :meth:`decide` for every request
    of the UAVs it serves, one at a time, in the order they arrive.

    The observation's arrays are views of the agent's shared memory, valid only during
    :meth:`decide` (use :meth:`setfleet.Observation.copy` to keep one). ``decide`` must return
    well within the request's ``deadline_ms`` (default 1000 ms): a late answer is dropped and
    the agent's fallback planner decides instead.
    """

    def reset(self) -> None:
        """Called before a run's first request (a planner may be reused across runs)."""

    def decide(self, obs: Observation) -> Decision:
        """The decision for request ``obs``: an :class:`~setfleet.Action`, a yaw increment
        (rad, in ``[-π, π]``), or a sequence of increments."""
        raise NotImplementedError

    def __call__(self, obs: Observation) -> Action:
        """:meth:`decide`, normalised to an :class:`~setfleet.Action`."""
        return as_action(self.decide(obs))


class FunctionPlanner(Planner):
    """A planner made of a function ``obs -> decision``."""

    def __init__(self, fn: Callable[[Observation], Any]) -> None:
        self.fn = fn

    def decide(self, obs: Observation) -> Decision:
        return self.fn(obs)

    def __repr__(self) -> str:
        return f"FunctionPlanner({self.fn!r})"


def as_planner(p: Any) -> Planner:
    """``p`` as a :class:`Planner`: a planner as is, a callable wrapped in
    :class:`FunctionPlanner`."""
    if isinstance(p, Planner):
        return p
    if callable(p):
        return FunctionPlanner(p)
    raise TypeError(f"a planner must be a setfleet.Planner or a callable, not {type(p).__name__}")
