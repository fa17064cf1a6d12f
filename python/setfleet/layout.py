"""The wire layout of a planner request and of its answer (``docs/python.md``).

An agent that asks an outside planner for its guidance decision sends a *request*: a fixed
512-byte header followed by twelve arrays, every number little-endian, every array at a
multiple of 8 bytes from the start of the payload. The planner replies with an *answer*: a
48-byte header, the yaw increments and the planned views.

The layout is defined once, in Rust (``protocol/src/plan/layout.rs``): ``cargo test -p
protocol`` checks this module's dtypes and constants, and the tables of ``docs/python.md``,
against it and names the first field that differs.

This module holds

- the numpy dtypes of both headers (:data:`REQUEST_HEADER`, :data:`ANSWER_HEADER`) and of the
  two table arrays (:data:`TARGET_ROW`, :data:`OTHER_ROW`);
- :class:`Observation`, a request decoded into zero-copy numpy views;
- the geometry of the planning and OEM grids (:class:`PlanGrid`, :class:`Grid`);
- :class:`Action` and :func:`as_action`, what a planner decides;
- :func:`encode_answer` and :func:`decode_answer` (the second checks what the agent checks);
- :func:`encode_request`, a pure-Python encoder of requests as the Rust agent writes them,
  for tests and for mock agents.

Lifetime of the views: an :class:`Observation` decoded from a request received over
iceoryx2 (:meth:`setfleet.Run.serve`, :meth:`setfleet.Run.next_request`) points into the
agent's shared memory. Its arrays are valid only until the request is answered, that is,
only during :meth:`setfleet.Planner.decide`. Keep :meth:`Observation.copy` (or copies of the
arrays you need) to use them later.
"""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass, field
from typing import Any, Iterable, Sequence

import numpy as np

__all__ = [
    "REQUEST_MAGIC",
    "ANSWER_MAGIC",
    "VERSION",
    "REQUEST_HEADER_BYTES",
    "ANSWER_HEADER_BYTES",
    "MAX_ANSWER_INCREMENTS",
    "MAX_ANSWER_VIEWS",
    "FLAG_ROUND_START",
    "KIND_INCREMENTS",
    "KIND_YAW_REF",
    "KIND_DEFER",
    "ARRAY_NAMES",
    "REQUEST_HEADER",
    "ANSWER_HEADER",
    "TARGET_ROW",
    "OTHER_ROW",
    "LayoutError",
    "ActionError",
    "Grid",
    "PlanGrid",
    "Camera",
    "Target",
    "Other",
    "Observation",
    "Action",
    "Answer",
    "as_action",
    "answer_size",
    "encode_answer",
    "encode_answer_for",
    "decode_answer",
    "encode_request",
    "run_tag",
    "DEFAULT_INCREMENTS",
]

#: ``magic`` of a request: the bytes ``SFPQ`` read as a little-endian ``u32``.
REQUEST_MAGIC = 0x51504653
#: ``magic`` of an answer: the bytes ``SFPA``.
ANSWER_MAGIC = 0x41504653
#: Version of both layouts described here.
VERSION = 1
#: Size of a request's header.
REQUEST_HEADER_BYTES = 512
#: Size of an answer's header.
ANSWER_HEADER_BYTES = 48
#: Most increments an answer may carry.
MAX_ANSWER_INCREMENTS = 64
#: Most planned views an answer may carry.
MAX_ANSWER_VIEWS = 256
#: Request ``flags`` bit 0: asked at the start of the round (``others`` is empty).
FLAG_ROUND_START = 1
#: Answer ``kind`` 0: yaw increments, the first applied now.
KIND_INCREMENTS = 0
#: Answer ``kind`` 1: a yaw reference.
KIND_YAW_REF = 1
#: Answer ``kind`` 2: defer, the UAV's own planner decides (increments and views ignored).
KIND_DEFER = 2

#: The request's arrays, in table order.
ARRAY_NAMES: tuple[str, ...] = (
    "increments",
    "undetected",
    "obstacle_neighbourhood",
    "unseen",
    "recently_hidden",
    "targets",
    "target_counts",
    "oem_height",
    "oem_status",
    "others",
    "poses",
    "fleet",
)
_N_ARRAYS = len(ARRAY_NAMES)
_ALIGN = 8


def _struct(fields: Sequence[tuple[str, str, int]], itemsize: int) -> np.dtype:
    """A structured dtype with explicit offsets (``(name, format, offset)``)."""
    return np.dtype(
        {
            "names": [f[0] for f in fields],
            "formats": [f[1] for f in fields],
            "offsets": [f[2] for f in fields],
            "itemsize": itemsize,
        }
    )


#: The request header, 512 bytes (``docs/python.md``, "The request"). ``arrays`` holds, for
#: each of the twelve arrays, its offset and its length in bytes.
REQUEST_HEADER: np.dtype = _struct(
    [
        ("magic", "<u4", 0),
        ("version", "<u2", 4),
        ("header_bytes", "<u2", 6),
        ("run_tag", "<u8", 8),
        ("step", "<u8", 16),
        ("round", "<u8", 24),
        ("total_steps", "<u8", 32),
        ("uav", "<u4", 40),
        ("fleet_size", "<u4", 44),
        ("steps_per_period", "<u4", 48),
        ("horizon", "<u4", 52),
        ("deadline_ms", "<u4", 56),
        ("flags", "<u4", 60),
        ("time_s", "<f8", 64),
        ("dt_s", "<f8", 72),
        ("speed_mps", "<f8", 80),
        ("max_yaw_rate_rps", "<f8", 88),
        ("x", "<f8", 96),
        ("y", "<f8", 104),
        ("z", "<f8", 112),
        ("yaw", "<f8", 120),
        ("camera_aperture_rad", "<f8", 128),
        ("camera_tilt_rad", "<f8", 136),
        ("camera_rows", "<u4", 144),
        ("camera_cols", "<u4", 148),
        ("plan_origin_x", "<f8", 152),
        ("plan_origin_y", "<f8", 160),
        ("plan_cell_m", "<f8", 168),
        ("plan_nx", "<u4", 176),
        ("plan_ny", "<u4", 180),
        ("count_cell_m2", "<f8", 184),
        ("oem_origin_x", "<f8", 192),
        ("oem_origin_y", "<f8", 200),
        ("oem_cell_m", "<f8", 208),
        ("oem_nx", "<u4", 216),
        ("oem_ny", "<u4", 220),
        ("border_half_m", "<f8", 224),
        ("undetected_m2", "<f8", 232),
        ("targets_m2", "<f8", 240),
        ("n_increments", "<u4", 248),
        ("n_targets", "<u4", 252),
        ("n_others", "<u4", 256),
        ("n_poses", "<u4", 260),
        ("n_fleet", "<u4", 264),
        ("n_target_counts", "<u4", 268),
        ("arrays", ("<u8", (12, 2)), 272),
    ],
    REQUEST_HEADER_BYTES,
)

#: The answer header, 48 bytes (``docs/python.md``, "The answer").
ANSWER_HEADER: np.dtype = _struct(
    [
        ("magic", "<u4", 0),
        ("version", "<u2", 4),
        ("kind", "<u2", 6),
        ("step", "<u8", 8),
        ("uav", "<u4", 16),
        ("n_increments", "<u4", 20),
        ("n_poses", "<u4", 24),
        ("reserved", "<u4", 28),
        ("yaw_ref", "<f8", 32),
        ("planner_ns", "<u8", 40),
    ],
    ANSWER_HEADER_BYTES,
)

#: A row of array 5, ``targets``: one identified car, 32 bytes.
TARGET_ROW: np.dtype = _struct(
    [
        ("id", "<u4", 0),
        ("x0", "<u4", 4),
        ("y0", "<u4", 8),
        ("w", "<u4", 12),
        ("h", "<u4", 16),
        ("first", "<u4", 20),
        ("area_m2", "<f8", 24),
    ],
    32,
)

#: A row of array 9, ``others``: the plan of a UAV ahead in the token, 16 bytes.
OTHER_ROW: np.dtype = _struct(
    [("uav", "<u4", 0), ("n_poses", "<u4", 4), ("first", "<u4", 8), ("pad", "<u4", 12)],
    16,
)

_RASTER = np.dtype("<u2")
_F8 = np.dtype("<f8")
_U4 = np.dtype("<u4")
_F4 = np.dtype("<f4")
_U1 = np.dtype("u1")

assert REQUEST_HEADER.itemsize == REQUEST_HEADER_BYTES
assert ANSWER_HEADER.itemsize == ANSWER_HEADER_BYTES
assert TARGET_ROW.itemsize == 32 and OTHER_ROW.itemsize == 16


class LayoutError(ValueError):
    """A request or an answer that does not follow the layout; the message says why."""


class ActionError(ValueError):
    """An action that cannot be encoded as a valid answer (the agent would refuse it)."""


def run_tag(run_id: str) -> int:
    """The run's tag as the header's ``run_tag`` carries it: 64-bit FNV-1a of the id."""
    h = 0xCBF29CE484222325
    for b in run_id.encode():
        h = ((h ^ b) * 0x100000001B3) & 0xFFFFFFFFFFFFFFFF
    return h


# --------------------------------------------------------------------------------------------
# Geometry


@dataclass(frozen=True)
class Grid:
    """A square-celled ground grid: cell ``(ix, iy)`` spans
    ``[origin_x + ix * cell_m, origin_x + (ix + 1) * cell_m)`` along x and likewise along y.
    Rasters over it are indexed ``[iy, ix]``, row 0 at the south."""

    origin_x: float
    origin_y: float
    cell_m: float
    nx: int
    ny: int

    @property
    def shape(self) -> tuple[int, int]:
        """``(ny, nx)``, the shape of a raster over the grid."""
        return (self.ny, self.nx)

    @property
    def extent(self) -> tuple[float, float, float, float]:
        """``(x_min, x_max, y_min, y_max)`` of the whole grid, m."""
        return (
            self.origin_x,
            self.origin_x + self.nx * self.cell_m,
            self.origin_y,
            self.origin_y + self.ny * self.cell_m,
        )

    @property
    def cell_area_m2(self) -> float:
        """Area of one cell, m²."""
        return self.cell_m * self.cell_m

    def centre(self, ix: Any, iy: Any) -> tuple[Any, Any]:
        """The centre ``(x, y)`` of cell ``(ix, iy)``, m (floats, or arrays for arrays)."""
        x = self.origin_x + (np.asarray(ix, dtype=float) + 0.5) * self.cell_m
        y = self.origin_y + (np.asarray(iy, dtype=float) + 0.5) * self.cell_m
        if x.ndim == 0 and y.ndim == 0:
            return float(x), float(y)
        return x, y

    def cell_centres(self) -> tuple[np.ndarray, np.ndarray]:
        """The centres of the columns and of the rows: ``xs`` of shape ``(nx,)`` and ``ys`` of
        shape ``(ny,)``; the centre of raster element ``[iy, ix]`` is ``(xs[ix], ys[iy])``
        (``np.meshgrid(xs, ys)`` gives both as ``(ny, nx)`` rasters)."""
        xs = self.origin_x + (np.arange(self.nx) + 0.5) * self.cell_m
        ys = self.origin_y + (np.arange(self.ny) + 0.5) * self.cell_m
        return xs, ys

    def cell_of(self, x: Any, y: Any) -> tuple[Any, Any]:
        """The cell ``(ix, iy)`` holding the point ``(x, y)`` (scalars give ints, arrays
        give int64 arrays). Points outside the grid give indices outside ``[0, nx)`` or
        ``[0, ny)``: check with :meth:`contains`."""
        fx = np.floor((np.asarray(x, dtype=float) - self.origin_x) / self.cell_m)
        fy = np.floor((np.asarray(y, dtype=float) - self.origin_y) / self.cell_m)
        if fx.ndim == 0 and fy.ndim == 0:
            return int(fx), int(fy)
        return fx.astype(np.int64), fy.astype(np.int64)

    def contains(self, ix: Any, iy: Any) -> Any:
        """Whether cell ``(ix, iy)`` is in the grid (a bool, or a bool array)."""
        inside = (
            (np.asarray(ix) >= 0)
            & (np.asarray(ix) < self.nx)
            & (np.asarray(iy) >= 0)
            & (np.asarray(iy) < self.ny)
        )
        return bool(inside) if inside.ndim == 0 else inside


@dataclass(frozen=True)
class PlanGrid(Grid):
    """The planning grid. Each planning cell is ``factor × factor`` estimator cells; the set
    rasters count, per planning cell, the estimator cells of the set (0 to
    :attr:`capacity`), and a count times :attr:`count_cell_m2` is an area in m²."""

    count_cell_m2: float = 0.0

    @property
    def factor(self) -> int:
        """Estimator cells per planning cell side (``plan_cell_m`` / estimator cell side)."""
        if self.count_cell_m2 <= 0:
            return 1
        return max(1, int(round(self.cell_m / math.sqrt(self.count_cell_m2))))

    @property
    def capacity(self) -> int:
        """The count of a planning cell wholly in a set: ``factor²``."""
        return self.factor * self.factor


@dataclass(frozen=True)
class Camera:
    """The asking UAV's camera."""

    aperture_rad: float
    tilt_rad: float
    rows: int
    cols: int


@dataclass(frozen=True, eq=False)
class Target:
    """An identified car: its set ``X_j`` as counts over a box of planning cells.

    ``counts`` is a ``(h, w)`` view (zero-copy, see the module's note on lifetimes) whose
    element ``[r, c]`` is cell ``(x0 + c, y0 + r)`` of the planning grid."""

    id: int
    x0: int
    y0: int
    w: int
    h: int
    area_m2: float
    counts: np.ndarray
    grid: PlanGrid = field(repr=False)

    @property
    def box(self) -> tuple[int, int, int, int]:
        """``(x0, y0, w, h)`` in planning cells."""
        return (self.x0, self.y0, self.w, self.h)

    @property
    def slices(self) -> tuple[slice, slice]:
        """The box as ``(rows, cols)`` slices of a planning raster."""
        return (slice(self.y0, self.y0 + self.h), slice(self.x0, self.x0 + self.w))

    def centre(self) -> tuple[float, float]:
        """The centre of the box, m."""
        g = self.grid
        return (
            g.origin_x + (self.x0 + self.w / 2) * g.cell_m,
            g.origin_y + (self.y0 + self.h / 2) * g.cell_m,
        )

    def dense(self) -> np.ndarray:
        """The counts as a full planning raster (``uint16``, shape ``(plan_ny, plan_nx)``,
        zero outside the box); a new array."""
        out = np.zeros(self.grid.shape, dtype=np.uint16)
        out[self.slices] = self.counts
        return out


@dataclass(frozen=True, eq=False)
class Other:
    """The plan of a UAV ahead in the token: its predicted camera poses ``(n, 4)``
    (``x, y, z, yaw``), a zero-copy view."""

    uav: int
    poses: np.ndarray


# --------------------------------------------------------------------------------------------
# Requests


def _as_bytes_view(payload: Any) -> memoryview:
    """``payload`` as a flat memoryview of bytes, without copying."""
    mv = memoryview(payload)
    if mv.ndim != 1 or mv.itemsize != 1 or mv.format not in ("B", "b", "c", "<B"):
        mv = mv.cast("B")
    return mv


def _view(mv: memoryview, dtype: np.dtype, count: int, offset: int) -> np.ndarray:
    """A read-only numpy view of ``count`` items of ``dtype`` at ``offset``."""
    if count == 0:
        a = np.empty(0, dtype=dtype)
    else:
        a = np.frombuffer(mv, dtype=dtype, count=count, offset=offset)
    a.flags.writeable = False
    return a


class Observation:
    """A planner request, decoded. Scalars are Python numbers; every array is a read-only
    zero-copy numpy view of the payload.

    **The views are valid only during** :meth:`setfleet.Planner.decide` when the payload is an
    agent's shared memory (the sample goes back to the agent once answered); call
    :meth:`copy` to keep an observation.

    Header fields: ``run_tag``, ``step``, ``round``, ``total_steps``, ``uav``, ``fleet_size``,
    ``steps_per_period``, ``horizon``, ``deadline_ms``, ``flags``, ``time_s``, ``dt_s``,
    ``speed_mps``, ``max_yaw_rate_rps``, ``x``, ``y``, ``z``, ``yaw``, ``camera``
    (:class:`Camera`), ``plan`` (:class:`PlanGrid`), ``oem`` (:class:`Grid`),
    ``border_half_m``, ``undetected_m2``, ``targets_m2``; ``header`` is the whole header as a
    0-d structured view (:data:`REQUEST_HEADER`).

    Arrays (``docs/python.md`` table): ``increments`` ``(n,)``, the set rasters
    ``undetected`` (X̄), ``obstacle_neighbourhood``, ``unseen`` (H̄) and ``recently_hidden``,
    each ``(plan_ny, plan_nx)`` ``uint16`` counts; ``target_table`` and ``target_counts``
    (raw arrays 5 and 6, also as :attr:`targets`); ``oem_height`` and ``oem_status``
    ``(oem_ny, oem_nx)``; ``others_table`` and ``poses`` (raw arrays 9 and 10, also as
    :attr:`others`); ``fleet``.
    """

    payload: memoryview

    def __init__(self, payload: Any) -> None:
        """Decodes ``payload`` (bytes, bytearray, memoryview or any buffer) without copying.

        Raises :class:`LayoutError` when the magic, the version, the header size, an array's
        offset, alignment or length, or a table entry does not follow the layout."""
        mv = _as_bytes_view(payload)
        n = mv.nbytes
        if n < REQUEST_HEADER_BYTES:
            raise LayoutError(
                f"request of {n} bytes is shorter than its {REQUEST_HEADER_BYTES}-byte header"
            )
        header = np.frombuffer(mv, dtype=REQUEST_HEADER, count=1, offset=0).reshape(())
        header.flags.writeable = False
        h = header
        magic = int(h["magic"])
        if magic != REQUEST_MAGIC:
            raise LayoutError(f"bad magic {magic:#010x} (expected {REQUEST_MAGIC:#010x}, 'SFPQ')")
        version = int(h["version"])
        if version != VERSION:
            raise LayoutError(f"unsupported version {version} (this reader knows {VERSION})")
        header_bytes = int(h["header_bytes"])
        if header_bytes != REQUEST_HEADER_BYTES:
            raise LayoutError(
                f"header_bytes is {header_bytes} (expected {REQUEST_HEADER_BYTES})"
            )

        self.payload = mv
        self.header = header
        self.run_tag: int = int(h["run_tag"])
        self.step: int = int(h["step"])
        self.round: int = int(h["round"])
        self.total_steps: int = int(h["total_steps"])
        self.uav: int = int(h["uav"])
        self.fleet_size: int = int(h["fleet_size"])
        self.steps_per_period: int = int(h["steps_per_period"])
        self.horizon: int = int(h["horizon"])
        self.deadline_ms: int = int(h["deadline_ms"])
        self.flags: int = int(h["flags"])
        self.time_s: float = float(h["time_s"])
        self.dt_s: float = float(h["dt_s"])
        self.speed_mps: float = float(h["speed_mps"])
        self.max_yaw_rate_rps: float = float(h["max_yaw_rate_rps"])
        self.x: float = float(h["x"])
        self.y: float = float(h["y"])
        self.z: float = float(h["z"])
        self.yaw: float = float(h["yaw"])
        self.camera = Camera(
            float(h["camera_aperture_rad"]),
            float(h["camera_tilt_rad"]),
            int(h["camera_rows"]),
            int(h["camera_cols"]),
        )
        self.plan = PlanGrid(
            float(h["plan_origin_x"]),
            float(h["plan_origin_y"]),
            float(h["plan_cell_m"]),
            int(h["plan_nx"]),
            int(h["plan_ny"]),
            float(h["count_cell_m2"]),
        )
        self.oem = Grid(
            float(h["oem_origin_x"]),
            float(h["oem_origin_y"]),
            float(h["oem_cell_m"]),
            int(h["oem_nx"]),
            int(h["oem_ny"]),
        )
        self.border_half_m: float = float(h["border_half_m"])
        self.undetected_m2: float = float(h["undetected_m2"])
        self.targets_m2: float = float(h["targets_m2"])

        n_inc = int(h["n_increments"])
        n_targets = int(h["n_targets"])
        n_others = int(h["n_others"])
        n_poses = int(h["n_poses"])
        n_fleet = int(h["n_fleet"])
        n_counts = int(h["n_target_counts"])
        plan_cells = self.plan.nx * self.plan.ny
        oem_cells = self.oem.nx * self.oem.ny
        # (dtype, item count, shape) of every array, in table order.
        specs: list[tuple[np.dtype, int, tuple[int, ...]]] = [
            (_F8, n_inc, (n_inc,)),
            (_RASTER, plan_cells, self.plan.shape),
            (_RASTER, plan_cells, self.plan.shape),
            (_RASTER, plan_cells, self.plan.shape),
            (_RASTER, plan_cells, self.plan.shape),
            (TARGET_ROW, n_targets, (n_targets,)),
            (_RASTER, n_counts, (n_counts,)),
            (_F4, oem_cells, self.oem.shape),
            (_U1, oem_cells, self.oem.shape),
            (OTHER_ROW, n_others, (n_others,)),
            (_F8, n_poses * 4, (n_poses, 4)),
            (_U4, n_fleet, (n_fleet,)),
        ]
        table = h["arrays"]
        views: list[np.ndarray] = []
        for i, (dtype, count, shape) in enumerate(specs):
            offset, length = int(table[i, 0]), int(table[i, 1])
            name = ARRAY_NAMES[i]
            expected = count * dtype.itemsize
            if length != expected:
                raise LayoutError(
                    f"array {i} ({name}) is {length} bytes, its counts give {expected}"
                )
            if offset % _ALIGN != 0:
                raise LayoutError(f"array {i} ({name}) at offset {offset}, not a multiple of 8")
            if length > 0 and offset < REQUEST_HEADER_BYTES:
                raise LayoutError(f"array {i} ({name}) at offset {offset}, inside the header")
            if offset + length > n:
                raise LayoutError(
                    f"array {i} ({name}) ends at {offset + length}, past the {n}-byte payload"
                )
            views.append(_view(mv, dtype, count, offset).reshape(shape))

        (
            self.increments,
            self.undetected,
            self.obstacle_neighbourhood,
            self.unseen,
            self.recently_hidden,
            self.target_table,
            self.target_counts,
            self.oem_height,
            self.oem_status,
            self.others_table,
            self.poses,
            self.fleet,
        ) = views

        targets = []
        for row in self.target_table:
            tid, x0, y0, w, hh, first = (int(row[k]) for k in ("id", "x0", "y0", "w", "h", "first"))
            if x0 + w > self.plan.nx or y0 + hh > self.plan.ny:
                raise LayoutError(
                    f"target {tid}: box ({x0}, {y0}, {w}, {hh}) outside the "
                    f"{self.plan.nx} x {self.plan.ny} planning grid"
                )
            if first + w * hh > n_counts:
                raise LayoutError(
                    f"target {tid}: counts {first}..{first + w * hh} past the "
                    f"{n_counts} target counts"
                )
            counts = self.target_counts[first : first + w * hh].reshape(hh, w)
            targets.append(Target(tid, x0, y0, w, hh, float(row["area_m2"]), counts, self.plan))
        self.targets: tuple[Target, ...] = tuple(targets)

        others = []
        for row in self.others_table:
            uav, k, first = int(row["uav"]), int(row["n_poses"]), int(row["first"])
            if first + k > n_poses:
                raise LayoutError(
                    f"plan of UAV {uav}: poses {first}..{first + k} past the {n_poses} poses"
                )
            others.append(Other(uav, self.poses[first : first + k]))
        self.others: tuple[Other, ...] = tuple(others)

    # ---- derived values --------------------------------------------------------------------

    @property
    def round_start(self) -> bool:
        """Whether the agent asked at the start of the round (``flags`` bit 0): the plans of
        the UAVs ahead are then not in :attr:`others`."""
        return bool(self.flags & FLAG_ROUND_START)

    @property
    def guidance_period_s(self) -> float:
        """Simulated seconds between two decisions of a UAV: ``steps_per_period * dt_s``."""
        return self.steps_per_period * self.dt_s

    @property
    def is_last_decision(self) -> bool:
        """Whether no decision of this UAV is left after this one before ``total_steps``."""
        return self.step + max(self.steps_per_period, 1) >= self.total_steps

    @property
    def pose(self) -> tuple[float, float, float, float]:
        """``(x, y, z, yaw)`` of the asking UAV's camera."""
        return (self.x, self.y, self.z, self.yaw)

    @property
    def factor(self) -> int:
        """Estimator cells per planning cell side (:attr:`PlanGrid.factor`)."""
        return self.plan.factor

    def fraction(self, raster: np.ndarray) -> np.ndarray:
        """A count raster as the fraction of each planning cell covered (``float32``, a new
        array): counts divided by ``factor²``."""
        return np.asarray(raster, dtype=np.float32) * np.float32(1.0 / self.plan.capacity)

    def targets_dense(self, combine: str = "sum") -> np.ndarray:
        """The union of the cars' sets as one planning raster of counts (``uint16``, a new
        array). The rasters hold counts, not cells, so overlapping sets cannot be told apart:
        ``combine="sum"`` adds the counts and clips them at ``factor²`` (an upper bound of the
        union's count), ``"max"`` keeps the largest (a lower bound)."""
        out = np.zeros(self.plan.shape, dtype=np.uint32)
        for t in self.targets:
            box = out[t.slices]
            if combine == "sum":
                box += t.counts
            elif combine == "max":
                np.maximum(box, t.counts, out=box)
            else:
                raise ValueError(f"combine must be 'sum' or 'max', not {combine!r}")
        np.minimum(out, self.plan.capacity, out=out)
        return out.astype(np.uint16)

    def copy(self) -> "Observation":
        """A copy that owns its bytes, valid after the request is answered."""
        return Observation(bytearray(self.payload))

    def __repr__(self) -> str:
        return (
            f"Observation(uav={self.uav}, step={self.step}, round={self.round}, "
            f"time_s={self.time_s}, pose=({self.x:.1f}, {self.y:.1f}, {self.z:.1f}, "
            f"{self.yaw:.3f}), plan={self.plan.nx}x{self.plan.ny}, "
            f"targets={len(self.targets)}, others={len(self.others)})"
        )


# --------------------------------------------------------------------------------------------
# Actions and answers


@dataclass
class Action:
    """What a planner decides for one request.

    - kind 0 (``yaw_ref is None``): ``increments``, 1 to 64 yaw increments in ``[-π, π]``;
      the first is applied now (``yaw_ref = yaw + increments[0]``), the others say what the
      planner means to do next.
    - kind 1 (``yaw_ref`` given): the yaw reference itself, rad; ``increments`` may still
      carry up to 64 values (or none).
    - kind 2 (``defer=True``, :meth:`deferred`): no decision; the UAV's own planner decides
      at once, as if no planner served it, but the answer counts as answered (and as
      ``deferred``), not as a fallback. For a planner that steps in only now and then.

    ``views`` is an optional ``(n, 4)`` array of planned camera poses ``x, y, z, yaw``
    (``n`` ≤ 256), shared through the token with the UAVs after this one.
    """

    increments: Any = ()
    yaw_ref: float | None = None
    views: Any = None
    defer: bool = False

    def __post_init__(self) -> None:
        if self.defer and self.yaw_ref is not None:
            raise ActionError("an action that defers has no yaw reference")
        self.increments = np.array(self.increments, dtype=np.float64).reshape(-1)
        if self.yaw_ref is not None:
            self.yaw_ref = float(self.yaw_ref)
        if self.views is not None:
            views = np.array(self.views, dtype=np.float64)
            if views.ndim != 2 or views.shape[1] != 4:
                raise ActionError(f"views must be an (n, 4) array, not shape {views.shape}")
            self.views = views

    @property
    def kind(self) -> int:
        """The answer's ``kind``: 0 for increments, 1 for a yaw reference, 2 to defer."""
        if self.defer:
            return KIND_DEFER
        return KIND_INCREMENTS if self.yaw_ref is None else KIND_YAW_REF

    @classmethod
    def turn(cls, *increments: float, views: Any = None) -> "Action":
        """Kind 0: ``Action.turn(0.5)`` turns by 0.5 rad now."""
        return cls(increments=increments, views=views)

    @classmethod
    def heading(cls, yaw_ref: float, views: Any = None) -> "Action":
        """Kind 1: fly toward the yaw reference ``yaw_ref``."""
        return cls(yaw_ref=yaw_ref, views=views)

    @classmethod
    def deferred(cls) -> "Action":
        """Kind 2: the UAV's own planner decides this time."""
        return cls(defer=True)


def as_action(value: Any) -> Action:
    """Normalises what a planner returned: an :class:`Action`; a number (one yaw increment);
    or a sequence / 1-D array of yaw increments. Raises :class:`ActionError` otherwise."""
    if isinstance(value, Action):
        return value
    if isinstance(value, (bool, np.bool_)) or value is None:
        raise ActionError(f"a planner must return an Action, a number or increments, not {value!r}")
    if isinstance(value, numbers.Real):
        return Action(increments=[float(value)])
    if isinstance(value, np.ndarray) and value.ndim == 0:
        return Action(increments=[float(value)])
    if isinstance(value, (Sequence, np.ndarray)) and not isinstance(value, (str, bytes)):
        try:
            return Action(increments=np.asarray(value, dtype=np.float64).reshape(-1))
        except (TypeError, ValueError) as e:
            raise ActionError(f"cannot read increments from {value!r}: {e}") from None
    raise ActionError(f"a planner must return an Action, a number or increments, not {value!r}")


def _check_action(action: Action) -> None:
    """Raises :class:`ActionError` for what the agent would refuse."""
    n = action.increments.size
    if action.kind == KIND_INCREMENTS:
        if not 1 <= n <= MAX_ANSWER_INCREMENTS:
            raise ActionError(f"{n} increments: an answer of kind 0 carries 1 to 64")
    else:
        if n > MAX_ANSWER_INCREMENTS:
            raise ActionError(f"{n} increments: an answer carries at most 64")
        if action.kind == KIND_YAW_REF and not math.isfinite(action.yaw_ref):  # type: ignore[arg-type]
            raise ActionError(f"yaw_ref {action.yaw_ref} is not finite")
    if n and not np.all(np.isfinite(action.increments)):
        raise ActionError("an increment is not finite")
    if n and np.any(np.abs(action.increments) > math.pi):
        raise ActionError(f"an increment is outside [-pi, pi]: {action.increments.tolist()}")
    if action.views is not None:
        if action.views.shape[0] > MAX_ANSWER_VIEWS:
            raise ActionError(f"{action.views.shape[0]} views: an answer carries at most {MAX_ANSWER_VIEWS}")
        if not np.all(np.isfinite(action.views)):
            raise ActionError("a view is not finite")


def answer_size(action: Action) -> int:
    """Bytes of the answer carrying ``action``: ``48 + 8 n_increments + 32 n_poses``."""
    n_views = 0 if action.views is None else action.views.shape[0]
    return ANSWER_HEADER_BYTES + 8 * action.increments.size + 32 * n_views


def encode_answer_for(step: int, uav: int, action: Any, planner_ns: int = 0) -> bytes:
    """The answer to the request of ``step`` from ``uav`` (see :func:`encode_answer`)."""
    action = as_action(action)
    _check_action(action)
    n_inc = action.increments.size
    n_views = 0 if action.views is None else action.views.shape[0]
    out = bytearray(answer_size(action))
    head = np.frombuffer(out, dtype=ANSWER_HEADER, count=1).reshape(())
    head["magic"] = ANSWER_MAGIC
    head["version"] = VERSION
    head["kind"] = action.kind
    head["step"] = step
    head["uav"] = uav
    head["n_increments"] = n_inc
    head["n_poses"] = n_views
    head["reserved"] = 0
    head["yaw_ref"] = 0.0 if action.yaw_ref is None else action.yaw_ref
    head["planner_ns"] = min(max(int(planner_ns), 0), 2**64 - 1)
    off = ANSWER_HEADER_BYTES
    np.frombuffer(out, dtype=_F8, count=n_inc, offset=off)[:] = action.increments
    off += 8 * n_inc
    if n_views:
        np.frombuffer(out, dtype=_F8, count=4 * n_views, offset=off)[:] = action.views.reshape(-1)
    return bytes(out)


def encode_answer(obs: Observation, action: Any, planner_ns: int = 0) -> bytes:
    """The answer to request ``obs`` carrying ``action`` (anything :func:`as_action`
    takes); ``planner_ns`` is the planner's own time on the decision (0 if unknown).

    Raises :class:`ActionError` for an action the agent would refuse (counts out of range, a
    number that is not finite, an increment outside ``[-π, π]``)."""
    return encode_answer_for(obs.step, obs.uav, action, planner_ns)


@dataclass(frozen=True)
class Answer:
    """An answer, decoded (:func:`decode_answer`)."""

    kind: int
    step: int
    uav: int
    increments: np.ndarray
    yaw_ref: float
    planner_ns: int
    views: np.ndarray

    def yaw_reference(self, yaw: float) -> float | None:
        """The yaw reference this answer sets for a UAV at yaw ``yaw`` (``None`` for kind 2:
        the UAV's own planner sets it)."""
        if self.kind == KIND_DEFER:
            return None
        return yaw + float(self.increments[0]) if self.kind == KIND_INCREMENTS else self.yaw_ref


def decode_answer(data: Any, *, step: int | None = None, uav: int | None = None) -> Answer:
    """Decodes and checks an answer as the agent does: magic, version, a kind of 0, 1 or 2, the
    request's ``step`` and ``uav`` (when given), counts in range, the length its counts give,
    every increment finite and in ``[-π, π]``, every view finite, and for kind 1 a finite
    ``yaw_ref`` (``reserved`` is not checked, nor kind 0's ``yaw_ref``). Raises
    :class:`LayoutError` naming the first reason."""
    mv = _as_bytes_view(data)
    n = mv.nbytes
    if n < ANSWER_HEADER_BYTES:
        raise LayoutError(f"answer of {n} bytes is shorter than its {ANSWER_HEADER_BYTES}-byte header")
    h = np.frombuffer(mv, dtype=ANSWER_HEADER, count=1).reshape(())
    if int(h["magic"]) != ANSWER_MAGIC:
        raise LayoutError(f"bad magic {int(h['magic']):#010x}")
    if int(h["version"]) != VERSION:
        raise LayoutError(f"unsupported version {int(h['version'])}")
    kind = int(h["kind"])
    if kind not in (KIND_INCREMENTS, KIND_YAW_REF, KIND_DEFER):
        raise LayoutError(f"unknown kind {kind}")
    if step is not None and int(h["step"]) != step:
        raise LayoutError(f"answer for step {int(h['step'])}, the request was step {step}")
    if uav is not None and int(h["uav"]) != uav:
        raise LayoutError(f"answer for UAV {int(h['uav'])}, the request was UAV {uav}")
    n_inc, n_views = int(h["n_increments"]), int(h["n_poses"])
    lo = 1 if kind == KIND_INCREMENTS else 0
    if not lo <= n_inc <= MAX_ANSWER_INCREMENTS:
        raise LayoutError(f"{n_inc} increments out of range {lo}..={MAX_ANSWER_INCREMENTS}")
    if n_views > MAX_ANSWER_VIEWS:
        raise LayoutError(f"{n_views} planned views out of range 0..={MAX_ANSWER_VIEWS}")
    expected = ANSWER_HEADER_BYTES + 8 * n_inc + 32 * n_views
    if n != expected:
        raise LayoutError(f"answer of {n} bytes, its counts give {expected}")
    yaw_ref = float(h["yaw_ref"])
    if kind == KIND_YAW_REF and not math.isfinite(yaw_ref):
        raise LayoutError("yaw_ref is not finite")
    incs = np.frombuffer(mv, dtype=_F8, count=n_inc, offset=ANSWER_HEADER_BYTES).copy()
    views = np.frombuffer(
        mv, dtype=_F8, count=4 * n_views, offset=ANSWER_HEADER_BYTES + 8 * n_inc
    ).reshape(n_views, 4).copy()
    if not np.all(np.isfinite(incs)):
        raise LayoutError("an increment is not finite")
    if np.any(np.abs(incs) > math.pi):
        raise LayoutError("an increment is outside [-pi, pi]")
    if not np.all(np.isfinite(views)):
        raise LayoutError("a planned view is not finite")
    return Answer(kind, int(h["step"]), int(h["uav"]), incs, yaw_ref, int(h["planner_ns"]), views)


# --------------------------------------------------------------------------------------------
# A pure-Python encoder of requests (tests, mock agents)

#: The paper's yaw increments, the scenario default (rad).
DEFAULT_INCREMENTS: tuple[float, ...] = (
    -math.pi / 3,
    -math.pi / 6,
    0.0,
    math.pi / 6,
    math.pi / 3,
)


def _raster(value: Any, shape: tuple[int, int], dtype: np.dtype, name: str) -> np.ndarray:
    if value is None:
        return np.zeros(shape, dtype=dtype)
    a = np.ascontiguousarray(value, dtype=dtype)
    if a.shape != shape:
        raise ValueError(f"{name} has shape {a.shape}, expected {shape}")
    return a


def encode_request(
    *,
    undetected: Any,
    step: int = 0,
    total_steps: int = 60,
    uav: int = 0,
    fleet_size: int = 1,
    steps_per_period: int = 6,
    horizon: int = 2,
    deadline_ms: int = 1000,
    round_start: bool = False,
    run_id: str | None = None,
    time_s: float | None = None,
    dt_s: float = 0.5,
    speed_mps: float = 10.0,
    max_yaw_rate_rps: float = 1.0,
    pose: Sequence[float] = (0.0, 0.0, 80.0, 0.0),
    camera: Camera = Camera(math.pi / 4, math.pi / 4, 360, 480),
    plan_origin: Sequence[float] | None = None,
    plan_cell_m: float = 2.5,
    count_cell_m2: float = 0.25,
    oem_origin: Sequence[float] | None = None,
    oem_cell_m: float = 5.0,
    border_half_m: float | None = None,
    undetected_m2: float | None = None,
    targets_m2: float | None = None,
    increments: Sequence[float] = DEFAULT_INCREMENTS,
    obstacle_neighbourhood: Any = None,
    unseen: Any = None,
    recently_hidden: Any = None,
    targets: Iterable[tuple[int, int, int, Any] | tuple[int, int, int, Any, float]] = (),
    oem_height: Any = None,
    oem_status: Any = None,
    oem_shape: tuple[int, int] | None = None,
    others: Iterable[tuple[int, Any]] = (),
    fleet: Sequence[int] | None = None,
) -> bytes:
    """A request as the agent lays it out (header, then arrays 0 to 11 in order, each at the
    next multiple of 8 bytes), for tests and mock agents.

    ``undetected`` (a ``(plan_ny, plan_nx)`` count raster) fixes the planning grid's size;
    the other rasters default to zeros. ``targets`` are ``(id, x0, y0, counts)`` with
    ``counts`` an ``(h, w)`` raster over the box, optionally with ``area_m2`` last (default:
    the counts' sum times ``count_cell_m2``). ``others`` are ``(uav, poses)`` with ``poses``
    ``(n, 4)``. The OEM grid's shape comes from ``oem_height``, ``oem_status`` or
    ``oem_shape`` (default: the region at ``oem_cell_m``). Unset values are derived as the
    agent derives them: ``round = step // steps_per_period``, ``time_s = step * dt_s``, the
    grids' origins at ``(-b, -b)`` for ``b = border_half_m`` (default: half the planning
    grid's width), ``undetected_m2`` and ``targets_m2`` from the counts.
    """
    und = np.ascontiguousarray(undetected, dtype=_RASTER)
    if und.ndim != 2:
        raise ValueError("undetected must be a 2-D raster")
    ny, nx = und.shape
    if border_half_m is None:
        border_half_m = nx * plan_cell_m / 2
    if plan_origin is None:
        plan_origin = (-border_half_m, -border_half_m)
    if oem_origin is None:
        oem_origin = plan_origin
    if oem_shape is None:
        for a in (oem_height, oem_status):
            if a is not None:
                oem_shape = np.shape(a)  # type: ignore[assignment]
                break
        else:
            side = max(1, int(math.ceil(nx * plan_cell_m / oem_cell_m)))
            oem_shape = (max(1, int(math.ceil(ny * plan_cell_m / oem_cell_m))), side)
    shape = (ny, nx)
    rasters = [
        und,
        _raster(obstacle_neighbourhood, shape, _RASTER, "obstacle_neighbourhood"),
        _raster(unseen, shape, _RASTER, "unseen"),
        _raster(recently_hidden, shape, _RASTER, "recently_hidden"),
    ]
    target_rows = []
    counts_parts = []
    first = 0
    for t in targets:
        tid, x0, y0, counts = t[0], t[1], t[2], np.ascontiguousarray(t[3], dtype=_RASTER)
        hh, w = counts.shape
        area = float(t[4]) if len(t) > 4 else float(counts.sum(dtype=np.uint64)) * count_cell_m2  # type: ignore[misc]
        target_rows.append((tid, x0, y0, w, hh, first, area))
        counts_parts.append(counts.reshape(-1))
        first += w * hh
    target_table = np.array(target_rows, dtype=TARGET_ROW)
    target_counts = (
        np.concatenate(counts_parts) if counts_parts else np.zeros(0, dtype=_RASTER)
    ).astype(_RASTER)
    other_rows = []
    pose_parts = []
    first = 0
    for o_uav, o_poses in others:
        p = np.ascontiguousarray(o_poses, dtype=_F8).reshape(-1, 4)
        other_rows.append((o_uav, p.shape[0], first, 0))
        pose_parts.append(p)
        first += p.shape[0]
    others_table = np.array(other_rows, dtype=OTHER_ROW)
    poses = np.concatenate(pose_parts) if pose_parts else np.zeros((0, 4), dtype=_F8)
    fleet_arr = np.asarray(list(range(fleet_size)) if fleet is None else fleet, dtype=_U4)
    arrays = [
        np.asarray(increments, dtype=_F8),
        *rasters,
        target_table,
        target_counts,
        _raster(oem_height, oem_shape, _F4, "oem_height"),  # type: ignore[arg-type]
        _raster(oem_status, oem_shape, _U1, "oem_status"),  # type: ignore[arg-type]
        others_table,
        poses,
        fleet_arr,
    ]

    table = np.zeros((_N_ARRAYS, 2), dtype=np.uint64)
    off = REQUEST_HEADER_BYTES
    for i, a in enumerate(arrays):
        off = (off + _ALIGN - 1) // _ALIGN * _ALIGN
        table[i] = (off, a.nbytes)
        off += a.nbytes
    out = bytearray(off)

    if undetected_m2 is None:
        undetected_m2 = float(und.sum(dtype=np.uint64)) * count_cell_m2
    if targets_m2 is None:
        targets_m2 = float(target_table["area_m2"].sum()) if len(target_table) else 0.0
    x, y, z, yaw = (float(v) for v in pose)
    head = np.frombuffer(out, dtype=REQUEST_HEADER, count=1).reshape(())
    values = {
        "magic": REQUEST_MAGIC,
        "version": VERSION,
        "header_bytes": REQUEST_HEADER_BYTES,
        "run_tag": 0 if run_id is None else run_tag(run_id),
        "step": step,
        "round": step // max(steps_per_period, 1),
        "total_steps": total_steps,
        "uav": uav,
        "fleet_size": fleet_size,
        "steps_per_period": steps_per_period,
        "horizon": horizon,
        "deadline_ms": deadline_ms,
        "flags": FLAG_ROUND_START if round_start else 0,
        "time_s": step * dt_s if time_s is None else time_s,
        "dt_s": dt_s,
        "speed_mps": speed_mps,
        "max_yaw_rate_rps": max_yaw_rate_rps,
        "x": x,
        "y": y,
        "z": z,
        "yaw": yaw,
        "camera_aperture_rad": camera.aperture_rad,
        "camera_tilt_rad": camera.tilt_rad,
        "camera_rows": camera.rows,
        "camera_cols": camera.cols,
        "plan_origin_x": plan_origin[0],
        "plan_origin_y": plan_origin[1],
        "plan_cell_m": plan_cell_m,
        "plan_nx": nx,
        "plan_ny": ny,
        "count_cell_m2": count_cell_m2,
        "oem_origin_x": oem_origin[0],
        "oem_origin_y": oem_origin[1],
        "oem_cell_m": oem_cell_m,
        "oem_nx": oem_shape[1],
        "oem_ny": oem_shape[0],
        "border_half_m": border_half_m,
        "undetected_m2": undetected_m2,
        "targets_m2": targets_m2,
        "n_increments": arrays[0].size,
        "n_targets": len(target_table),
        "n_others": len(others_table),
        "n_poses": poses.shape[0],
        "n_fleet": fleet_arr.size,
        "n_target_counts": target_counts.size,
        "arrays": table,
    }
    for k, v in values.items():
        head[k] = v
    for (off, length), a in zip(table.tolist(), arrays):
        out[off : off + length] = a.tobytes()
    return bytes(out)
