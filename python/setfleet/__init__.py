"""setfleet's Python side: guidance planners in Python for the fleet's agents.

An agent started with ``fleet run --planner external:...`` asks an outside process for its
guidance decisions over iceoryx2 (``docs/python.md``). This package is that process:

- :class:`Run` starts (or joins) a run and answers its agents' requests;
- :class:`Planner` is the interface of a planner, :class:`Action` what it decides;
- :class:`Observation` is a request decoded into zero-copy numpy views (:mod:`setfleet.layout`);
- :func:`read_summary`, :func:`read_timeseries`, :func:`read_tracks` read a run's outputs;
- :mod:`setfleet.gym` holds the Gymnasium and PettingZoo environments (extra ``gym``).
"""

from .layout import (
    Action,
    ActionError,
    Answer,
    LayoutError,
    Observation,
    as_action,
    decode_answer,
    encode_answer,
    encode_request,
)
from .planner import FunctionPlanner, Planner
from .results import read_summary, read_timeseries, read_tracks
from .run import Request, RequestHandle, Run, RunEnded, RunResult, find_fleet, fleet_supports_planner

__version__ = "0.1.0"

__all__ = [
    "Run",
    "RunResult",
    "RunEnded",
    "Request",
    "RequestHandle",
    "Planner",
    "FunctionPlanner",
    "Observation",
    "Action",
    "Answer",
    "ActionError",
    "LayoutError",
    "as_action",
    "encode_answer",
    "decode_answer",
    "encode_request",
    "read_summary",
    "read_timeseries",
    "read_tracks",
    "find_fleet",
    "fleet_supports_planner",
]
