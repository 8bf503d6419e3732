"""The learner's end of the motor path: the lockstep client of a running simulator.

:class:`~.fleet_client.FleetClient` flies every vehicle of a simulator process in rounds
of SET_ACTUATOR_CONTROL_TARGET, through its socket (:mod:`.fleet_link`);
:class:`~.motor_client.MotorClient` is that client with one vehicle, flown with
HIL_ACTUATOR_CONTROLS. It speaks the words of :mod:`quadsitl.wire` and reads its answers
with its :func:`~quadsitl.wire.answer.decode_answer`; it needs nothing of the
simulator's server.
"""
