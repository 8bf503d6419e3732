"""Mission files that ``quadsitl fly`` reads.

* **QGroundControl .plan** (JSON, what QGC's Plan view saves): ``{"fileType": "Plan",
  "mission": {"items": [...]}}``. A ``SimpleItem`` has ``command``, ``frame``, ``params``
  (7 values, ``null`` for NaN: 1-4, latitude, longitude, altitude) and ``autoContinue``;
  a ``ComplexItem`` (Survey, Corridor Scan) carries the items QGC generated for it in
  ``TransectStyleComplexItem.Items``. The plan's geofence and rally points are not
  uploaded (the simulator keeps those lists empty).
* **Waypoint list** (any other file): one waypoint a line, ``EAST NORTH UP [HOLD]`` in
  metres from home (and seconds); ``#`` starts a comment. Flown as ``make demo`` flies its
  mission: take-off to the first waypoint's height, the others in order, land at home.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

from gcs_tools.client import MissionItem, Waypoint

Mission = list[MissionItem] | tuple[Waypoint, ...]


def read_mission(path: str | Path) -> Mission:
    """The mission in ``path``; ValueError naming the file and the problem."""
    path = Path(path)
    try:
        text = path.read_text()
    except (OSError, UnicodeDecodeError) as error:
        reason = getattr(error, "strerror", None) or error
        raise ValueError(f"cannot read {path}: {reason}") from None
    if text.lstrip().startswith("{"):
        return read_plan(text, path)
    return read_waypoints(text, path)


def read_plan(text: str, path: Path) -> list[MissionItem]:
    try:
        plan = json.loads(text)
    except json.JSONDecodeError as error:
        raise ValueError(f"{path} is not valid JSON: {error}") from None
    if not isinstance(plan, dict) or plan.get("fileType") != "Plan":
        raise ValueError(f'{path} is not a QGroundControl plan (no "fileType": "Plan")')
    entries = (plan.get("mission") or {}).get("items")
    if not isinstance(entries, list) or not entries:
        raise ValueError(f"{path}: the plan has no mission items")
    items: list[MissionItem] = []
    for number, entry in enumerate(entries, 1):
        items += _plan_items(entry, f"{path}: mission item {number}")
    return items


def _plan_items(entry: Any, where: str) -> list[MissionItem]:
    if not isinstance(entry, dict):
        raise ValueError(f"{where} is not an object")
    if entry.get("type") == "ComplexItem":
        generated = (entry.get("TransectStyleComplexItem") or {}).get("Items")
        if not isinstance(generated, list):
            kind = entry.get("complexItemType", "?")
            raise ValueError(f"{where} ({kind}) holds no generated items to fly")
        return [_simple_item(item, f"{where} ({kind})") for item in generated]
    return [_simple_item(entry, where)]


def _simple_item(entry: Any, where: str) -> MissionItem:
    try:
        command, frame = int(entry["command"]), int(entry["frame"])
        params = [math.nan if value is None else float(value) for value in entry["params"]]
    except (KeyError, TypeError, ValueError):
        raise ValueError(f"{where} needs command, frame and params (7 numbers)") from None
    if len(params) != 7:
        raise ValueError(f"{where} has {len(params)} params, not 7")
    return MissionItem(
        command,
        latitude=params[4],
        longitude=params[5],
        altitude=params[6],
        params=(params[0], params[1], params[2], params[3]),
        frame=frame,
        autocontinue=bool(entry.get("autoContinue", True)),
    )


def read_waypoints(text: str, path: Path) -> tuple[Waypoint, ...]:
    waypoints = []
    for number, line in enumerate(text.splitlines(), 1):
        words = line.split("#", 1)[0].split()
        if not words:
            continue
        try:
            values = [float(word) for word in words]
        except ValueError:
            values = []
        if len(values) not in (3, 4) or not all(math.isfinite(v) for v in values):
            raise ValueError(
                f"{path}:{number}: a waypoint is EAST NORTH UP [HOLD] (numbers, m and s), "
                f"got {line.strip()!r}"
            )
        waypoints.append(Waypoint(*values))
    if not waypoints:
        raise ValueError(f"{path}: no waypoints (a line is EAST NORTH UP [HOLD])")
    if waypoints[0].up <= 0:
        raise ValueError(f"{path}: the first waypoint sets the take-off height; it must be > 0")
    return tuple(waypoints)
