"""The wire vocabulary both ends of the motor path share: the simulator's server
(:mod:`quadsitl.mavlink`) and the lockstep clients (:mod:`quadsitl.client`).

- :mod:`.dialect`: ``mavlink``, pymavlink's ``development`` dialect (``common`` plus
  the messages being standardised, such as AVAILABLE_MODES);
- :mod:`.units`: the wire's units (``time_usec``; Ω = u·Ω_max), free of pymavlink;
- :mod:`.fast_codec`: MAVLink 2 frames packed and parsed with ``struct``;
- :mod:`.state`: :class:`~.state.WireState`, the vehicle state in wire frames;
- :mod:`.lockstep`: the motor path's commands, flags and limits;
- :mod:`.answer`: a state answer, built (:func:`~.answer.answer_parts`) and read back
  (:func:`~.answer.decode_answer`).

Nothing here opens a socket or knows the vehicle: both ends import it, it imports
neither.
"""
