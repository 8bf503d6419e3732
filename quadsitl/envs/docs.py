"""The Gymnasium docstring template, filled in from a task's spec (its words, which the
task builds from its constants) and shared pieces."""

from __future__ import annotations

from quadsitl.registration import versioned_ids
from quadsitl.tasks import TaskOptions, TaskSpec
from quadsitl.tasks import features as F

ROTOR_ORDER = "Rotor order: ``paper`` plus layout 1 front, 2 left, 3 back, 4 right."
ACTION_SPACE = {
    0: """## Action Space
``Box(-Ω_h/β, (Ω_max − Ω_h)/β, (4,), float32)`` ≈ [−6.45, 2.67] for the paper airframe:
one raw policy output per rotor. Eq. 19 maps it to a commanded rotor speed
``Ω_c = Ω_h + β·a`` (β = 35 rad/s by default); the box is exactly the rotor range
[0, Ω_max], and larger actions are accepted and clipped to it, as in the paper.
""",
    1: """## Action Space
``Box(-1, 1, (4,), float32)``, one value per rotor, mapped affinely onto v0's action
range [low, high] = [−Ω_h/β, (Ω_max − Ω_h)/β]: ``a_v0 = ((1 − a)·low + (1 + a)·high)/2``,
so −1 and +1 are v0's bounds exactly and the commanded rotor speed is
``Ω_c = Ω_max·(a + 1)/2`` (0 is half the top speed, below hover: hovering is
``a = 2·Ω_h/Ω_max − 1`` ≈ 0.41 for the paper airframe). Larger actions are clipped to
±1. The reward's action penalty reads the v0 value, so a flight earns what it earns in
v0.
""",
}

OBSERVATION_SPACE = """## Observation Space
``Box(-inf, inf, ({size},), float32)``, frames ENU (world) and FLU (body):

| index | observation | unit |
|---|---|---|
| 0–2 | position relative to the task origin | m |
| 3–5, 6–8 | sin and cos of (roll, pitch, yaw) | – |
| 9–11 | linear velocity, body frame | m/s |
| 12–14 | body rates | rad/s |
| 15–18 | rotor speeds Ω/Ω_max | 0–1 |
| 19–21 | goal position − position | m |
| 22–24, 25–27 | sin, cos of goal attitude (level) − sin, cos of attitude | – |
| 28–30 | goal velocity − velocity, body frame | m/s |
| 31–33 | goal rates (0) − body rates | rad/s |
{extra}"""

EXTRA_OBS_ROW = "| {columns} | {meaning} | {unit} |"

ARGUMENTS = """## Arguments
Keyword arguments of ``gymnasium.make(id, **kwargs)`` (all optional; unknown names raise
``ValueError``): ``airframe`` ("paper" | "paper-x"), ``physics_dt`` (s, 0.01),
``control_period`` (s, 0.05, a whole number of physics steps), ``episode_seconds``
(default {seconds} s), ``beta`` (rad/s, 35), ``init_position_noise`` (m),
``init_attitude_noise`` (rad), ``init_velocity_noise`` (m/s), ``init_rate_noise`` (rad/s)
(uniform half-widths added to the start; 0 = the paper's start) and
``param_randomization`` (``{{"mass": 0.1, ...}}``: per episode, scale each named airframe
parameter by U(1 − f, 1 + f)), ``delay`` (``{{"observation": s, "action": s}}``, seconds
or (low, high) drawn per episode), ``randomize`` (True: airframe, wind and delay drawn per
episode; docs/tasks.md), ``airframe_scale`` (``{{"mass": 1.3}}``: exact scales),
``wind`` (a Wind or ``{{"speed": 6, "from_deg": 270, "turbulence": "moderate"}}``),
``sensor_noise`` (0: exact observations; 1: as the sensors measure them),
``ground_effect`` (True: rotor thrust grows near the ground), ``faults``
(``{{"motor": 2, "efficiency": 0.6, "at": 1.0}}``: a motor that loses thrust during every
episode), ``observe_position`` (False: columns 0–2 read 0), ``observe_integral``
(True: three more columns, the clamped integral of columns 19–21 over the episode,
m·s; docs/tasks.md) and ``proximity_reward`` (``{{"weight": 15, "radius": 0.5}}``: every
step also earns w·max(0, 1 − d/r) for the distance d to the goal). ``render_mode``:
None; "rgb_array" (``render()`` returns a top and a side view of the vehicle, an
(H, W, 3) uint8 frame, one per step at ``metadata["render_fps"]``; "human": Gymnasium's
pygame window over them); or "rerun" to log every
episode to a Rerun viewer (or to the .rrd file ``rerun_save``).

Episode-end ``info`` keys: ``outcome`` (timed_out, out_of_bounds, flipped, landed,
landed_off_pad, crashed), ``success``, ``final_distance`` (m), ``time_within_threshold``
(s), ``reach_time`` (s, NaN if never), ``crashed``, ``episode_return``,
``episode_length``, ``touchdown_speed`` (m/s, NaN if airborne)."""

START_V1 = """
Defaults of this version: the task's evaluation start, as ``quadsitl eval`` flies it:
{defaults}; pass the options (e.g. ``init_position_noise=0``) to change them."""

VERSION_HISTORY = """## Version History
* v1: actions normalised to ``Box(-1, 1)`` (mapped affinely onto v0's range), and the
  evaluation start by default; the same physics, task, reward and options. For new work.
* v0: {history}
  Kept as it was for the shipped checkpoints and published results."""
PAPER_HISTORY = """the paper's task, without the original code's bugs (stale distances at reset,
  inconsistent rotor observation, inverse Euler angles, wrong crash geometry)."""
OWN_HISTORY = "a task of quadsitl's own (not in the paper)."


def env_doc(task: TaskSpec, version: int = 0) -> str:
    """Assemble the docstring of ``task``'s env of ``version`` in the Gymnasium template."""
    doc, seconds = task.doc, task.episode_seconds
    start = doc.start
    if version >= 1:
        defaults = ", ".join(f"``{k}={v!r}``" for k, v in task.train_start.items())
        start += START_V1.format(defaults=defaults)
    steps = max(1, round(seconds / TaskOptions().control_period))
    extra = "\n".join(
        EXTRA_OBS_ROW.format(columns=_columns(block), meaning=meaning, unit=unit)
        for block, meaning, unit in task.extra_obs_layout
    )
    return "\n\n".join(
        [
            f"# {versioned_ids(version)[task.env_name]}",
            f"## Description\n{doc.description}",
            ACTION_SPACE[version] + ROTOR_ORDER,
            OBSERVATION_SPACE.format(size=F.OBS_SIZE + task.extra_obs, extra=extra),
            f"## Rewards\n{doc.rewards}",
            f"## Starting State\n{start}",
            f"## Episode End\n{doc.end}; truncated after {seconds:g} s ({steps} steps). "
            f"Success: {task.success_text()}.",
            ARGUMENTS.format(seconds=seconds),
            VERSION_HISTORY.format(history=PAPER_HISTORY if task.paper else OWN_HISTORY),
        ]
    )


def _columns(block: slice) -> str:
    """``34–36`` (or ``37`` for one column)."""
    last = block.stop - 1
    return f"{block.start}" if last == block.start else f"{block.start}–{last}"
