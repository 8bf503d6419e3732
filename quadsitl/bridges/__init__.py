"""Real flight stacks flying quadsitl's physics: the simulator leads, the autopilot follows.

In this mode quadsitl's own flight software is off and the process is only the aircraft:
each adapter turns an autopilot's motor outputs into rotor commands, steps the batched
physics in lockstep with it, and answers with what that autopilot's simulator interface
expects (docs/autopilots.md). The protocol logic of each adapter is IO-free; its sockets
live in a module of their own.
"""

from __future__ import annotations

FLIGHT_STACKS = ("ardupilot", "px4")
"""Names accepted by ``quadsitl sim --flight-stack``."""
