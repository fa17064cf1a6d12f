"""The UAVs' flight model, as the world flies them (``protocol/src/flight.rs``), for planners
that predict where a yaw reference takes a UAV.

A UAV flies at a constant ground speed and altitude; its yaw moves toward the yaw reference
the shortest way round at no more than the yaw-rate bound and stops exactly on it. While the
yaw turns the path is a circular arc, then a straight segment.
"""

from __future__ import annotations

import math

__all__ = ["wrap_angle", "advance", "footprint_centre"]


def wrap_angle(a: float) -> float:
    """``a`` wrapped into ``(-π, π]``, bit for bit as the Rust side does (an angle already in
    ``[0, π]`` is returned unchanged)."""
    tau = 2 * math.pi
    w = math.fmod(a, tau)
    if w < 0:
        w += tau
    if w > math.pi:
        w -= tau
    return w


def advance(
    x: float,
    y: float,
    yaw: float,
    yaw_ref: float,
    dt: float,
    speed_mps: float,
    max_yaw_rate_rps: float,
) -> tuple[float, float, float]:
    """Where ``(x, y, yaw)`` is ``dt`` seconds later, flying at ``speed_mps`` while the yaw
    follows ``yaw_ref`` at no more than ``max_yaw_rate_rps``: ``(x, y, yaw)``, the yaw in
    ``(-π, π]``. A reference exactly opposite the yaw turns counter-clockwise."""
    if not (math.isfinite(dt) and dt > 0):
        return x, y, yaw
    speed = speed_mps if math.isfinite(speed_mps) and speed_mps > 0 else 0.0
    rate = max_yaw_rate_rps if math.isfinite(max_yaw_rate_rps) and max_yaw_rate_rps > 0 else 0.0
    yaw0 = wrap_angle(yaw)
    target = wrap_angle(yaw_ref) if math.isfinite(yaw_ref) else yaw0
    error = wrap_angle(target - yaw0)
    sign = 1.0 if error > 0 else -1.0
    if error == 0.0:
        turn_time, omega, final = 0.0, 0.0, yaw0
    elif rate * dt >= abs(error):
        turn_time, omega, final = abs(error) / rate, rate * sign, target
    else:
        turn_time, omega, final = dt, rate * sign, wrap_angle(yaw0 + rate * dt * sign)
    if turn_time > 0:
        turned = omega * turn_time
        if abs(turned) < 1e-9:
            mid = yaw0 + turned / 2
            x += speed * turn_time * math.cos(mid)
            y += speed * turn_time * math.sin(mid)
        else:
            r = speed / omega
            x += r * (math.sin(yaw0 + turned) - math.sin(yaw0))
            y -= r * (math.cos(yaw0 + turned) - math.cos(yaw0))
    straight = dt - turn_time
    if straight > 0:
        x += speed * straight * math.cos(final)
        y += speed * straight * math.sin(final)
    return x, y, final


def footprint_centre(
    x: float, y: float, z: float, yaw: float, tilt_rad: float, ground_z: float = 0.0
) -> tuple[float, float]:
    """Where the camera's optical axis meets flat ground at ``ground_z``: ``(x, y)`` ahead of
    the UAV by ``(z - ground_z) / tan(tilt)`` (the UAV's own position for a vertical
    axis)."""
    if tilt_rad <= 0:
        return x, y
    ahead = (z - ground_z) / math.tan(tilt_rad)
    return x + ahead * math.cos(yaw), y + ahead * math.sin(yaw)
