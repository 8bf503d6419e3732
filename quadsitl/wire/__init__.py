"""The wire vocabulary both ends share: the simulator's server (:mod:`quadsitl.simulator`)
and the bridges on one end, the lockstep clients (:mod:`quadsitl.lockstep_client`) and the
ground station (``gcs_tools``) on the other.

- :mod:`.dialect`: ``mavlink``, pymavlink's ``development`` dialect (``common`` plus
  the messages being standardised, such as AVAILABLE_MODES);
- :mod:`.units`: the wire's units (``time_usec``; Ω = u·Ω_max), free of pymavlink;
- :mod:`.fast_codec`: MAVLink 2 frames packed and parsed with ``struct``;
- :mod:`.state`: :class:`~.state.WireState`, the vehicle state in wire frames;
- :mod:`.lockstep`: the motor path's commands, flags and limits;
- :mod:`.answer`: a state answer, built (:func:`~.answer.answer_parts`) and read back
  (:func:`~.answer.decode_answer`);
- :mod:`.addresses`: link URLs, the loopback rule, the datagram limit, a free port;
- :mod:`.signing`: signing keys, and signing what a pymavlink connection sends;
- :mod:`.param_values`: how a parameter's value travels (bytewise integers);
- :mod:`.modes`: the flight modes in PX4's ``custom_mode`` layout;
- :mod:`.ids`, :mod:`.statustext`, :mod:`.fit`: system ids, long texts in chunks,
  values fitted to their wire types.

Only this package of quadsitl imports pymavlink. Nothing here keeps a socket open or
knows the vehicle: both ends import it, it imports neither.
"""
